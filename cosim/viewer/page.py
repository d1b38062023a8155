"""The dashboard page: one self-contained HTML document (inline CSS and JS, no build step, no external assets).

The script polls ``/api/state`` (about 4 times a second, with ``setTimeout``: nothing spins), swaps an image
panel's ``src`` when that panel's frame changes, and marks each panel with the frame it shows in its
``data-frame`` attribute, and the frames it has shown in ``data-seen`` (what the headless-browser test reads).
The auger chart and the fullness bars are
drawn on canvases, at their shown size, from the numbers in the state, each with its legend; each fullness bar
takes its label and colour from the state (cosim.viewer.fill), and its canvas keeps them in ``data-labels`` and
``data-status``.

Layout: a two-column grid that fills the page's width (one column below 900 px): the camera images, the camera
sensors across the page, then the height maps across the page, the two LiDAR views, the auger chart and the
fullness bars. A replay adds a bar
under the header: step back, play / pause, step on, and a slider to seek (``POST /api/replay``).
"""
from __future__ import annotations

import json

from .fill import STATUSES
from .panels import IMAGE_PANELS, PANELS

__all__ = ["page_html", "POLL_MS"]

#: the page's polling period, ms
POLL_MS = 250
#: shortest time between two refreshes of one image panel, ms (each refresh costs the viewer an encode)
IMAGE_MIN_MS = 500

_CSS = """
html,body{height:100%}
body{margin:0;background:#111418;color:#e6e6e6;font:14px system-ui,sans-serif}
header{display:flex;flex-wrap:wrap;gap:8px 24px;align-items:baseline;padding:10px 16px;background:#1b2027;
  border-bottom:1px solid #333}
header h1{font-size:17px;margin:0}
header .v{font-variant-numeric:tabular-nums;font-weight:600}
#status.running{color:#7fdc7f}#status.ended,#status.finished{color:#f0c060}#status.error{color:#ff7070}
#replay{display:none;align-items:center;gap:10px;padding:6px 16px;background:#171b21;border-bottom:1px solid #333}
#replay.on{display:flex}
#replay button{background:#2c333d;color:#e6e6e6;border:1px solid #445;border-radius:4px;padding:3px 10px;
  font:13px system-ui,sans-serif;cursor:pointer;min-width:64px}
#replay input[type=range]{flex:1}
#rp-pos{font-variant-numeric:tabular-nums;min-width:150px;text-align:right}
main{display:grid;grid-template-columns:repeat(2,minmax(0,1fr));gap:12px;padding:12px;
  grid-template-areas:"rgb depth" "cameras cameras" "heightmaps heightmaps" "lidar_top lidar_side" "auger fullness"}
@media (max-width:900px){main{grid-template-columns:minmax(0,1fr);grid-template-areas:"rgb" "depth" "cameras"
  "heightmaps" "lidar_top" "lidar_side" "auger" "fullness"}}
section.panel{background:#1b2027;border:1px solid #2c333d;border-radius:6px;padding:8px;min-width:0}
section.panel h2{font-size:14px;margin:0 0 6px 0;display:flex;justify-content:space-between}
section.panel h2 .f{color:#9ab;font-weight:400}
section.panel img{width:100%;height:auto;display:block}
#p-rgb img,#p-depth img{max-height:min(38vh,420px);object-fit:contain;image-rendering:auto}
section.panel canvas{width:100%;height:260px;display:block}
section.absent{opacity:.55}section.absent .body{display:none}
.note{color:#9ab;font-size:12px}
"""

_JS = """
const POLL_MS = %(poll)d, IMAGE_MIN_MS = %(image_min)d, IMAGE_PANELS = %(image_panels)s, FILL = %(fill)s;
const lastFetch = {};
let ended = false;  // the run has ended: its last images are fetched at once, and kept when the viewer goes
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
    if (img.dataset.want !== String(info.frame) && (ended || !(now - (lastFetch[id] || 0) < IMAGE_MIN_MS))) {
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
function canvas(id) {  // a canvas drawn at its shown size (sharp at any width)
  const c = $(id), w = Math.max(200, Math.round(c.clientWidth)), h = Math.max(120, Math.round(c.clientHeight));
  if (c.width !== w || c.height !== h) { c.width = w; c.height = h; }
  const g = c.getContext("2d"); g.fillStyle = "#181c22"; g.fillRect(0, 0, w, h); g.font = "12px sans-serif";
  return [c, g];
}
function legend(g, x, y, items) {  // items: [label, colour, "box" | "line"]
  items.forEach(([label, col, kind]) => {
    g.fillStyle = col; g.strokeStyle = col;
    if (kind === "line") { g.lineWidth = 2; g.beginPath(); g.moveTo(x, y - 4); g.lineTo(x + 16, y - 4); g.stroke();
                           g.lineWidth = 1; }
    else g.fillRect(x, y - 10, 14, 10);
    g.fillStyle = "#ccc"; g.fillText(label, x + 20, y); x += 28 + g.measureText(label).width;
  });
}
function drawAuger(a) {
  const [c, g] = canvas("c-auger");
  const L = 58, T = 28, W = c.width - L - 12, H = c.height - T - 34;
  g.strokeStyle = "#444"; g.strokeRect(L, T, W, H);
  legend(g, L, 16, [["desired", "#f0c060", "line"], ["actual", "#60b0ff", "line"]]);
  g.fillStyle = "#9ab"; g.fillText("time (s)", L + W / 2 - 20, c.height - 4);
  g.save(); g.translate(12, T + H / 2 + 40); g.rotate(-Math.PI / 2); g.fillText("auger x in cart (m)", 0, 0); g.restore();
  if (!a || !a.t.length) return;
  const all = a.desired.concat(a.actual).filter((v) => v !== null && isFinite(v));
  if (!all.length) return;
  let lo = Math.min(...all), hi = Math.max(...all); if (hi - lo < 0.5) { lo -= 0.25; hi += 0.25; }
  const t0 = a.t[0], t1 = Math.max(a.t[a.t.length - 1], t0 + 1e-6);
  const X = (t) => L + (t - t0) / (t1 - t0) * W, Y = (v) => T + (hi - v) / (hi - lo) * H;
  g.fillStyle = "#9ab";
  [lo, (lo + hi) / 2, hi].forEach((v) => g.fillText(v.toFixed(2), 22, Y(v) + 4));
  [t0, (t0 + t1) / 2, t1].forEach((t, i) => g.fillText(t.toFixed(1), X(t) - (i ? (i === 2 ? 30 : 12) : 0), T + H + 15));
  [["desired", "#f0c060"], ["actual", "#60b0ff"]].forEach(([k, col], i) => {
    g.strokeStyle = col; g.lineWidth = 2; g.beginPath(); let first = true;
    a[k].forEach((v, j) => { if (v === null) return; if (first) { g.moveTo(X(a.t[j]), Y(v)); first = false; }
                             else g.lineTo(X(a.t[j]), Y(v)); });
    g.stroke(); g.lineWidth = 1;
    g.fillStyle = col; g.fillText(k + " " + fmt(a[k][a[k].length - 1], 2) + " m", c.width - 260 + 130 * i, 16);
  });
}
function drawFullness(f) {  // labels and statuses come with the state (one rule: cosim.viewer.fill)
  const [c, g] = canvas("c-fullness");
  const L = 46, T = 28, H = c.height - T - 40, top = 1.2;
  legend(g, L, 16, Object.values(FILL).map(([label, col]) => [label, col, "box"])
                   .concat([["target (100 %%)", "#f0c060", "line"]]));
  g.fillStyle = "#9ab"; g.fillText("section (1 = front)", c.width / 2 - 50, c.height - 4);
  c.dataset.labels = f ? f.labels.join("|") : ""; c.dataset.status = f ? f.status.join("|") : "";
  if (!f || !f.values.length) return;
  const n = f.values.length, W = (c.width - L - 10) / n;
  const Y = (v) => T + H * (1 - Math.min(Math.max(v, 0), top) / top);
  g.fillStyle = "rgba(127, 220, 127, 0.12)";  // the band at the target the outcome allows
  g.fillRect(L, Y(f.band[1]), c.width - 6 - L, Math.max(1, Y(f.band[0]) - Y(f.band[1])));
  [0, 0.5, 1].forEach((v) => { g.fillStyle = "#9ab"; g.fillText(Math.round(v * 100) + " %%", 4, Y(v) + 4); });
  f.values.forEach((v, i) => {
    const ok = f.status[i] !== "unknown", h = ok ? T + H - Y(v) : H;
    g.fillStyle = FILL[f.status[i]][1];
    g.fillRect(L + i * W + 3, T + H - h, W - 6, h);
    g.fillStyle = "#ddd"; g.fillText(f.labels[i], L + i * W + W / 2 - 14, Math.min(T + H - h - 4, T + H - 4));
    g.fillStyle = "#ccc"; g.fillText(String(i + 1), L + i * W + W / 2 - 4, T + H + 16);
  });
  g.strokeStyle = "#f0c060"; g.lineWidth = 2; g.beginPath(); g.moveTo(L, Y(1)); g.lineTo(c.width - 6, Y(1)); g.stroke();
  g.lineWidth = 1;
}
let seeking = false;
function showReplay(r) {
  const bar = $("replay"); if (!r) return; bar.classList.add("on");
  $("rp-play").textContent = r.playing ? "pause" : "play"; $("rp-play").dataset.playing = r.playing ? "1" : "0";
  const sl = $("rp-seek"); sl.min = r.first; sl.max = r.last;
  if (!seeking) sl.value = r.frame;
  $("rp-pos").textContent = "frame " + r.frame + " of " + r.first + ".." + r.last;
  bar.dataset.frame = String(r.frame);
}
async function replay(action, value) {
  const q = "action=" + action + (value === undefined ? "" : "&value=" + value);
  const r = await fetch("/api/replay?" + q, {method: "POST"});
  if (r.ok) showReplay(await r.json());
}
function wireReplay() {
  $("rp-play").onclick = () => replay($("rp-play").dataset.playing === "1" ? "pause" : "play");
  $("rp-back").onclick = () => replay("step", -1);
  $("rp-fwd").onclick = () => replay("step", 1);
  const sl = $("rp-seek");
  sl.oninput = () => { seeking = true; $("rp-pos").textContent = "frame " + sl.value; };
  sl.onchange = () => { seeking = false; replay("seek", sl.value); };
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
    ended = s.status === "run ended";
    for (const [id, info] of Object.entries(s.panels)) setPanel(id, info);
    drawAuger(s.auger); drawFullness(s.fullness); showReplay(s.replay);
  } catch (e) {
    // after the run's end the viewer goes away: its last frame stays on screen, still "run ended"
    if (ended) { $("status").title = "the viewer has closed with the run"; return; }
    const st = $("status"); st.textContent = "viewer unreachable"; st.className = "error";
  }
  setTimeout(poll, POLL_MS);
}
wireReplay();
poll();
"""


def _panel(pid: str, title: str) -> str:
    body = (f'<img alt="{title}">' if pid in IMAGE_PANELS else
            f'<canvas id="c-{pid}" width="640" height="260"></canvas>')
    return (f'<section class="panel absent" id="p-{pid}" style="grid-area:{pid}" data-frame="" data-seen="" '
            f'data-available="0">'
            f'<h2><span>{title}</span><span class="f"></span></h2><div class="note"></div>'
            f'<div class="body">{body}</div></section>')


_REPLAY_BAR = ('<div id="replay"{on}><button id="rp-back" title="one frame back">&#9664; step</button>'
               '<button id="rp-play" data-playing="1">pause</button>'
               '<button id="rp-fwd" title="one frame on">step &#9654;</button>'
               '<input id="rp-seek" type="range" min="0" max="0" step="1" value="0" aria-label="seek">'
               '<span id="rp-pos">-</span></div>')


def page_html(title: str = "graincosim viewer", replay: bool = False) -> str:
    """The whole dashboard document; ``replay`` shows the replay bar (play / pause / step / seek) from the
    start (the page also shows it once ``/api/state`` has a ``replay`` position)."""
    panels = "\n".join(_panel(pid, t) for pid, t in PANELS.items())
    ids = "[" + ", ".join(f'"{p}"' for p in IMAGE_PANELS) + "]"
    js = _JS % {"poll": POLL_MS, "image_min": IMAGE_MIN_MS, "image_panels": ids, "fill": json.dumps(STATUSES)}
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<meta name="viewport" content="width=device-width, initial-scale=1"><style>{_CSS}</style></head>
<body><header><h1>graincosim viewer</h1><span>run <span class="v" id="run">-</span></span>
<span>frame <span class="v" id="frame" data-frame="">-</span><span id="planned"></span></span>
<span>sim time <span class="v" id="simt">-</span></span><span>real-time factor <span class="v" id="rtf">-</span></span>
<span>dropped <span class="v" id="dropped">0</span></span><span class="v" id="status">connecting</span></header>
{_REPLAY_BAR.format(on=' class="on"' if replay else '')}
<main>
{panels}
</main>
<script>{js}</script></body></html>
"""
