"""The input surfaces of cameras, terrain, the atmosphere and FMU archives: every hostile value is refused by
``validate`` before anything starts, exit 2 at its own key with file:line:col, no traceback, within bounded memory
and time (docs/reliability.md, "Before anything starts"). The values here are variants of the ones the limits were
written for, so that a limit fitted to one value only fails."""
from __future__ import annotations

import os
import pickle
import resource
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from cosim.errors import ScenarioError
from cosim.scenario.config.terrain import MAX_TERRAIN_CELLS
from cosim.scenario.loader import load_scenario, resolve_scenario_arg
from cosim.scenario.sizes import CAMERA_PIXEL_BUDGET, camera_problems
from cosim.world.height_map import HeightMapError, read_height_map

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = resolve_scenario_arg("default")
#: address space the validate subprocess may map: an interpreter with numpy, trimesh and pydantic, no more
ADDRESS_SPACE = 2 << 30
MOUNT = "{parent: combine, xyz_m: [-3.5, 5.0, 6.0], rpy_deg: [0.0, 52.0, 116.0]}"


def _validate(*args: str, cwd: Path | None = None) -> tuple[int, str, float]:
    """``launch.py validate ARGS`` in a subprocess whose address space is limited: (exit code, stderr + stdout,
    wall seconds)."""
    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))

    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    t = time.perf_counter()
    r = subprocess.run([sys.executable, str(ROOT / "launch.py"), "validate", *args], capture_output=True, text=True,
                       preexec_fn=limit, env=env, cwd=cwd or ROOT, timeout=300)
    return r.returncode, r.stderr + r.stdout, time.perf_counter() - t


def _refused_at(out: str, key: str, file: str) -> str:
    """The one line of ``out`` that reports ``key`` in ``file`` (file:line:col: key: message)."""
    assert "Traceback" not in out, out
    lines = [ln for ln in out.splitlines() if f": {key}: " in ln]
    assert lines, out
    head = lines[0].split(f": {key}: ")[0]
    assert head.startswith(file) and head[len(file):].count(":") == 2, lines[0]
    return lines[0]


@pytest.mark.parametrize("setting, key", [
    ("terrain={roughness_rms_m: 0.02, cell_m: 0.06, tile_m: 900}", "terrain.tile_m"),
    ("terrain={grade_pct: 3, cell_m: 0.08, render_extent_m: 300}", "terrain.render_extent_m"),
    ("atmosphere.dust_window_s=[55, 12]", "atmosphere.dust_window_s[1]"),
    ("atmosphere.dust_window_s=[-5, 12]", "atmosphere.dust_window_s[0]"),
    ("atmosphere.overlap_m=[2.5, 1.5]", "atmosphere.overlap_m[1]"),
    ("atmosphere.visibility_m=0.002", "atmosphere.visibility_m"),
    ("atmosphere.dust_mass_g_m3=4000", "atmosphere.dust_mass_g_m3"),
    ("atmosphere.dust_mass_g_m3=30", "atmosphere.dust_mass_g_m3"),           # MOR 0.2 m: beyond the densest
    ("atmosphere.kernel_diameter_m=0.4", "atmosphere.kernel_diameter_m"),
    ("atmosphere.kernel_diameter_m=1e-7", "atmosphere.kernel_diameter_m"),
    ("atmosphere.lidar_ratio_sr=5e4", "atmosphere.lidar_ratio_sr"),
    ("atmosphere.beam_divergence_mrad=900", "atmosphere.beam_divergence_mrad"),
    ("atmosphere.mass_extinction_m2_per_g=500", "atmosphere.mass_extinction_m2_per_g"),
])
def test_hostile_values_are_refused_at_their_key(setting, key):
    code, out, wall = _validate("default", "--set", setting)
    assert code == 2, out
    _refused_at(out, key, "<--set>")
    assert wall < 60, wall                      # refused from the numbers: nothing was drawn or built


def test_visibility_and_dust_mass_together_are_refused():
    code, out, _ = _validate("default", "--set", "atmosphere.visibility_m=35", "--set",
                             "atmosphere.dust_mass_g_m3=0.2")
    assert code == 2
    assert "not both" in _refused_at(out, "atmosphere.dust_mass_g_m3", "<--set>")


def test_a_packaged_dust_window_and_visibility_stay_valid():
    s = load_scenario(resolve_scenario_arg("dense_dust"), ["field.draw=[]"])   # the file's values, nothing drawn
    assert s.atmosphere.dust_window_s == (40.0, 70.0) and s.atmosphere.visibility_m == 20.0


def _cameras(tmp_path: Path, n: int, width: int, height: int, kind: str = "depth_camera", extra: str = "") -> Path:
    body = "".join(f"  cam{i}:\n    kind: {kind}\n    width_px: {width}\n    height_px: {height}\n"
                   f"    range_max_m: 8.0\n{extra}    mount: {MOUNT}\n" for i in range(n))
    path = tmp_path / "cameras.yaml"
    path.write_text(f"format_version: 1\nextends: default\nsensors:\n{body}")
    return path


@pytest.mark.parametrize("n, width, height, key", [
    (12, 2048, 2048, "sensors.cam2"),           # the third takes the frame past the budget
    (40, 320, 240, "sensors"),                  # more sensors than a scenario may have
])
def test_too_many_camera_pixels_are_refused_at_validate(tmp_path, n, width, height, key):
    path = _cameras(tmp_path, n, width, height)
    code, out, wall = _validate(str(path))
    assert code == 2, out
    _refused_at(out, key, str(path))
    assert wall < 60, wall


def test_a_stereo_pair_counts_both_views(tmp_path):
    path = _cameras(tmp_path, 1, 2304, 2048, kind="stereo_camera", extra="    baseline_m: 0.2\n")
    s = load_scenario(path, check_world=False)
    assert [loc for loc, _ in camera_problems(s)] == [("sensors", "cam0")]       # 2 x 4.7 Mpx > the budget
    assert 2304 * 2048 <= CAMERA_PIXEL_BUDGET < 2 * 2304 * 2048


def test_camera_memory_is_checked_against_what_the_machine_has(tmp_path):
    s = load_scenario(_cameras(tmp_path, 2, 1024, 1024), check_world=False)
    assert camera_problems(s, free=(1 << 40, 1 << 40, 1 << 40)) == []
    [(loc, message)] = camera_problems(s, free=(1 << 20, 1 << 40, 1 << 40))
    assert loc == ("sensors",) and "/dev/shm has 1.0 MiB free" in message


def test_the_memory_check_counts_at_least_what_the_depth_noise_model_takes_a_pixel():
    import importlib.util

    from cosim.scenario.sizes import CAMERA_PROCESS_BYTES_PER_PIXEL

    spec = importlib.util.spec_from_file_location("camera_pixel_cost", ROOT / "bench" / "camera_pixel_cost.py")
    cost = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(cost)
    z, pin, cam = cost.noise_model_input(640, 480)
    counted = CAMERA_PROCESS_BYTES_PER_PIXEL * z.size
    assert 0.8 * counted <= cost.peak_bytes(z, pin, cam) <= counted + 64 * 1024   # + a few small arrays a frame


def test_a_stereo_baseline_below_a_millimetre_is_refused(tmp_path):
    path = _cameras(tmp_path, 1, 640, 480, kind="stereo_camera", extra="    baseline_m: 2.0e-9\n")
    with pytest.raises(ScenarioError, match="baseline_m: Input should be greater than or equal to 0.005 m"):
        load_scenario(path)


# ------------------------------------------------------------------------------------------- height maps
def _pickled(path: Path) -> None:
    np.save(path, np.array([[{"a": 1}, 2], [3, 4]], dtype=object), allow_pickle=True)


def _truncated(path: Path) -> None:
    np.save(path, np.zeros((40, 40)))
    path.write_bytes(path.read_bytes()[:900])


HEIGHT_MAPS = {
    "empty": (lambda p: p.write_bytes(b""), "an empty file"),
    "text": (lambda p: p.write_text("0.0 0.1 0.2\n0.3 0.4 0.5\n"), "a text file"),
    "raw pickle": (lambda p: p.write_bytes(pickle.dumps([[0.0, 1.0], [2.0, 3.0]])), "pickled data"),
    "object array": (_pickled, "object"),
    "truncated": (_truncated, "truncated"),
    "header only": (lambda p: p.write_bytes(np.lib.format.MAGIC_PREFIX + b"\x01\x00"), "truncated or damaged"),
    "magic only": (lambda p: p.write_bytes(np.lib.format.MAGIC_PREFIX), "truncated or damaged"),
    "version 9": (lambda p: p.write_bytes(np.lib.format.MAGIC_PREFIX + b"\x09\x00" + b" " * 64), "version"),
    "npz": (lambda p: np.savez(p.with_suffix(".npz"), a=np.zeros((3, 3))) or p.with_suffix(".npz").rename(p),
            "zip archive"),
    "complex": (lambda p: np.save(p, np.zeros((4, 4), np.complex128)), "complex128"),
    "strings": (lambda p: np.save(p, np.array([["a", "b"], ["c", "d"]])), "<U1"),
    "one row": (lambda p: np.save(p, np.zeros((1, 30))), "at least 2 x 2"),
    "3-D": (lambda p: np.save(p, np.zeros((3, 3, 3))), "2-D"),
    "NaN": (lambda p: np.save(p, np.where(np.eye(5) > 0, np.nan, 0.0)), "not finite"),
    "a kilometre too high": (lambda p: np.save(p, np.full((3, 3), 3e6)), "beyond"),
    "too many samples": (lambda p: np.save(p, np.zeros((2, MAX_TERRAIN_CELLS // 2 + 8), np.uint8)), "at most"),
}


@pytest.mark.parametrize("name", list(HEIGHT_MAPS))
def test_a_bad_height_map_is_refused_at_its_key_and_never_unpickled(tmp_path, name):
    make, says = HEIGHT_MAPS[name]
    make(tmp_path / "field.npy")
    with pytest.raises(HeightMapError, match=None) as info:
        read_height_map(tmp_path / "field.npy")
    assert says in str(info.value) and "allow_pickle=True" not in str(info.value)
    (tmp_path / "s.yaml").write_text("format_version: 1\nextends: default\nterrain:\n  height_map_file: field.npy\n")
    code, out, _ = _validate(str(tmp_path / "s.yaml"))
    assert code == 2, out
    line = _refused_at(out, "terrain.height_map_file", str(tmp_path / "s.yaml"))
    assert line.startswith(f"{tmp_path / 's.yaml'}:4:20:") and says in line and "allow_pickle" not in out


def test_a_good_height_map_reads_as_float64(tmp_path):
    np.save(tmp_path / "field.npy", np.arange(12, dtype=np.int16).reshape(3, 4))
    heights = read_height_map(tmp_path / "field.npy")
    assert heights.dtype == np.float64 and heights.shape == (3, 4) and heights[2, 3] == 11.0


# ------------------------------------------------------------------------------------------ FMU archives
def _evil_fmu(path: Path, member: str, link: bool = False) -> None:
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("modelDescription.xml", '<fmiModelDescription fmiVersion="2.0"/>')
        info = zipfile.ZipInfo(member)
        if link:
            info.external_attr = (0o120777 << 16)
        zf.writestr(info, "/etc/passwd" if link else "x")


@pytest.mark.parametrize("member, link, says", [
    ("/tmp/graincosim-evil.txt", False, "is absolute"),
    ("resources/../../outside.txt", False, "climbs out"),
    ("binaries\\linux64\\x.so", False, "backslash"),
    ("C:evil.txt", False, "is absolute or names a drive"),
    ("resources/data", True, "symbolic link"),
])
def test_an_fmu_archive_is_checked_as_fmpy_extracts_it(tmp_path, member, link, says):
    pytest.importorskip("fmpy", reason="FMU checks need fmpy (pip install -e \".[test]\")")
    text = (ROOT / "examples" / "fmu_vehicle" / "scenario.yaml").read_text()
    (tmp_path / "scenario.yaml").write_text(text)
    _evil_fmu(tmp_path / "TractorCart.fmu", member, link)
    code, out, _ = _validate(str(tmp_path / "scenario.yaml"))
    assert code == 2, out
    assert says in _refused_at(out, "vehicles.tractor_cart.fmu.path", str(tmp_path / "scenario.yaml"))
    assert not Path("/tmp/graincosim-evil.txt").exists()
