"""The dashboard page: one self-contained HTML document (inline CSS and JS, no build step, no external assets).

The script polls ``/api/state`` (about 4 times a second, with ``setTimeout``: nothing spins), swaps an image
panel's ``src`` when that panel's frame changes, and marks each panel with the frame it shows in its
``data-frame`` attribute, and the frames it has shown in ``data-seen`` (what the headless-browser test reads).
The auger chart and the fullness bars are
drawn on canvases from the numbers in the state.
"""
from __future__ import annotations

from .panels import IMAGE_PANELS, PANELS

__all__ = ["page_html", "POLL_MS"]

#: the page's polling period, ms
POLL_MS = 250
#: shortest time between two refreshes of one image panel, ms (each refresh costs the viewer an encode)
IMAGE_MIN_MS = 500

_CSS = """
body{margin:0;background:#111418;color:#e6e6e6;font:14px system-ui,sans-serif}
header{display:flex;gap:24px;align-items:baseline;padding:10px 16px;background:#1b2027;border-bottom:1px solid #333}
header h1{font-size:17px;margin:0}
header .v{font-variant-numeric:tabular-nums;font-weight:600}
#status.running{color:#7fdc7f}#status.ended,#status.finished{color:#f0c060}#status.error{color:#ff7070}
main{display:grid;grid-template-columns:repeat(auto-fill,minmax(440px,1fr));gap:12px;padding:12px}
section.panel{background:#1b2027;border:1px solid #2c333d;border-radius:6px;padding:8px;min-height:120px}
section.panel h2{font-size:13px;margin:0 0 6px 0;display:flex;justify-content:space-between}
section.panel h2 .f{color:#9ab;font-weight:400}
section.panel img{width:100%;height:auto;display:block;image-rendering:pixelated}
section.panel canvas{max-width:100%;display:block}
section.absent{opacity:.55}section.absent .body{display:none}
.note{color:#9ab;font-size:12px}
"""

_JS = """
const POLL_MS = %(poll)d, IMAGE_MIN_MS = %(image_min)d, IMAGE_PANELS = %(image_panels)s;
const lastFetch = {};
const $ = (id) => document.getElementById(id);
function shown(sec, f) {
  sec.dataset.frame = String(f); sec.querySelector(".f").textContent = "frame " + f;
  const seen = sec.dataset.seen ? sec.dataset.seen.split(" ") : [];
  if (seen[seen.length - 1] !== String(f)) { seen.push(String(f)); sec.dataset.seen = seen.slice(-20).join(" "); }
}
function fmt(x, d) { return (x === null || x === undefined || !isFinite(x)) ? "-" : x.toFixed(d); }
function setPanel(id, info) {
  const sec = $("p-" + id); if (!sec) return;
  sec.classList.toggle("absent", !info.available);
  sec.dataset.available = info.available ? "1" : "0";
  sec.querySelector(".note").textContent = info.available ? "" : info.note;
  if (!info.available || info.frame === null) return;
  if (IMAGE_PANELS.includes(id)) {
    const img = sec.querySelector("img");
    const now = Date.now();
    if (img.dataset.want !== String(info.frame) && !(now - (lastFetch[id] || 0) < IMAGE_MIN_MS)) {
      lastFetch[id] = now;
      img.dataset.want = String(info.frame);
      const f = info.frame;
      img.onload = () => shown(sec, f);
      img.src = "/panel/" + id + ".png?frame=" + f;
    }
  } else {
    shown(sec, info.frame);
  }
}
function drawAuger(a) {
  const c = $("c-auger"), g = c.getContext("2d"); g.fillStyle = "#181c22"; g.fillRect(0, 0, c.width, c.height);
  if (!a || !a.t.length) return;
  const all = a.desired.concat(a.actual).filter((v) => v !== null && isFinite(v));
  if (!all.length) return;
  let lo = Math.min(...all), hi = Math.max(...all); if (hi - lo < 0.5) { lo -= 0.25; hi += 0.25; }
  const t0 = a.t[0], t1 = Math.max(a.t[a.t.length - 1], t0 + 1e-6), W = c.width - 50, H = c.height - 30;
  const X = (t) => 45 + (t - t0) / (t1 - t0) * W, Y = (v) => 10 + (hi - v) / (hi - lo) * H;
  g.strokeStyle = "#444"; g.strokeRect(45, 10, W, H); g.fillStyle = "#9ab"; g.font = "11px sans-serif";
  g.fillText(hi.toFixed(2) + " m", 2, 18); g.fillText(lo.toFixed(2) + " m", 2, 10 + H);
  g.fillText(t0.toFixed(1) + " s", 45, c.height - 4); g.fillText(t1.toFixed(1) + " s", 45 + W - 40, c.height - 4);
  [["desired", "#f0c060"], ["actual", "#60b0ff"]].forEach(([k, col], i) => {
    g.strokeStyle = col; g.beginPath(); let first = true;
    a[k].forEach((v, j) => { if (v === null) return; if (first) { g.moveTo(X(a.t[j]), Y(v)); first = false; }
                             else g.lineTo(X(a.t[j]), Y(v)); });
    g.stroke(); g.fillStyle = col; g.fillText(k + " " + fmt(a[k][a[k].length - 1], 2) + " m", 60 + 140 * i, 24);
  });
}
function drawFullness(f) {
  const c = $("c-fullness"), g = c.getContext("2d"); g.fillStyle = "#181c22"; g.fillRect(0, 0, c.width, c.height);
  if (!f || !f.values.length) return;
  const n = f.values.length, W = (c.width - 40) / n, H = c.height - 40, top = 1.2;
  const y100 = 10 + H * (1 - 1 / top);
  g.strokeStyle = "#f0c060"; g.beginPath(); g.moveTo(30, y100); g.lineTo(c.width, y100); g.stroke();
  g.font = "11px sans-serif";
  f.values.forEach((v, i) => {
    const ok = v !== null && isFinite(v), h = ok ? Math.min(v, top) / top * H : 0;
    g.fillStyle = ok ? (v >= 1 ? "#7fdc7f" : "#60b0ff") : "#555";
    g.fillRect(34 + i * W, 10 + H - h, W - 6, h);
    g.fillStyle = "#ccc"; g.fillText(String(i + 1), 34 + i * W + W / 2 - 6, c.height - 16);
    g.fillText(ok ? Math.round(v * 100) + "%%" : "?", 34 + i * W, c.height - 3);
  });
  g.fillStyle = "#9ab"; g.fillText("100%%", 0, 14 + H * (1 - 1 / top));
}
async function poll() {
  try {
    const r = await fetch("/api/state", {cache: "no-store"});
    const s = await r.json();
    $("run").textContent = s.run; $("frame").textContent = s.frame < 0 ? "-" : s.frame;
    $("frame").dataset.frame = String(s.frame);
    $("planned").textContent = s.frames_planned === null ? "" : " / " + s.frames_planned;
    $("simt").textContent = fmt(s.t_s, 2) + " s"; $("rtf").textContent = fmt(s.rtf, 2) + "x";
    $("dropped").textContent = String(s.dropped_total);
    const st = $("status"); st.textContent = s.status;
    st.className = s.status === "run ended" ? "ended" : s.status;
    for (const [id, info] of Object.entries(s.panels)) setPanel(id, info);
    drawAuger(s.auger); drawFullness(s.fullness);
  } catch (e) {
    const st = $("status"); st.textContent = "viewer unreachable"; st.className = "error";
  }
  setTimeout(poll, POLL_MS);
}
poll();
"""


def _panel(pid: str, title: str) -> str:
    body = (f'<img alt="{title}">' if pid in IMAGE_PANELS else
            f'<canvas id="c-{pid}" width="520" height="{240 if pid == "auger" else 200}"></canvas>')
    return (f'<section class="panel absent" id="p-{pid}" data-frame="" data-seen="" data-available="0">'
            f'<h2><span>{title}</span><span class="f"></span></h2><div class="note"></div>'
            f'<div class="body">{body}</div></section>')


def page_html(title: str = "graincosim viewer") -> str:
    """The whole dashboard document."""
    panels = "\n".join(_panel(pid, t) for pid, t in PANELS.items())
    ids = "[" + ", ".join(f'"{p}"' for p in IMAGE_PANELS) + "]"
    js = _JS % {"poll": POLL_MS, "image_min": IMAGE_MIN_MS, "image_panels": ids}
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<meta name="viewport" content="width=device-width, initial-scale=1"><style>{_CSS}</style></head>
<body><header><h1>graincosim viewer</h1><span>run <span class="v" id="run">-</span></span>
<span>frame <span class="v" id="frame" data-frame="">-</span><span id="planned"></span></span>
<span>sim time <span class="v" id="simt">-</span></span><span>real-time factor <span class="v" id="rtf">-</span></span>
<span>dropped <span class="v" id="dropped">0</span></span><span class="v" id="status">connecting</span></header>
<main>
{panels}
</main>
<script>{js}</script></body></html>
"""
