"""The run's outcome (cosim.runtime.outcome): whether the job was done, with its reason, on the console, in
log.txt, summary.json and ``--require-filled``'s exit code."""
from __future__ import annotations

import json

import numpy as np
import pytest

from cosim.cli import EXIT_NOT_FILLED, main
from cosim.runtime.outcome import HOLD_LOST, HOLD_NO_MEASUREMENT, judge, outcome_line
from cosim.scenario.config import Scenario

SC = Scenario.model_validate({"format_version": 1, "feedback": "ground_truth", "renderer": "none"})
TARGET = SC.controller.target_fill_m


def _summary(peaks, spill_kg=0.0, completed=True, **kw):
    return {"fill": {"section_peak_height_m": list(peaks)}, "spill": {"mass_kg": spill_kg}, "completed": completed,
            "status": "completed" if completed else "failed", "sim_time_s": 60.0, **kw}


def _series(n=601, auger=True, all_full=False, hold=0, flow_end=0.0, cart_valid=None, sigma=0.01):
    t = np.arange(n) * 0.1
    s = {"dyn_state.t_s": t, "dyn_state.auger_on": np.full(n, 1.0 if auger else 0.0),
         "dyn_state.all_full": np.full(n, float(all_full)), "dyn_state.hold_reason": np.full(n, float(hold)),
         "dyn_state.flow_level": np.r_[np.ones(n - 1), flow_end], "dyn_state.estimate_sigma_m": np.full(n, sigma)}
    if hold:
        s["dyn_state.hold_reason"][: n // 2] = 0
    if cart_valid is not None:
        s["perc_state.cart_valid"] = np.asarray(cart_valid, float)
    return s


def test_a_cart_filled_to_target_is_filled():
    out = judge(SC, _summary([TARGET - 0.01] * 9), _series(all_full=True))
    assert out["status"] == "filled" and out["sections_at_target"] == 9


@pytest.mark.parametrize("peaks, spill, words", [
    ([TARGET] * 8 + [TARGET + 0.15], 0.0, "overfill 15 cm in section 9"),
    ([TARGET] * 9, 120.0, "spill 120 kg"),
])
def test_spill_or_overfill_fails_the_job_with_the_numbers(peaks, spill, words):
    out = judge(SC, _summary(peaks, spill), _series(all_full=True))
    assert out["status"] == "job_failed" and words in out["reason"]


def test_perception_that_never_found_the_cart_is_a_safe_stop_never_a_success():
    out = judge(SC, _summary([1.0] * 9), _series(n=1201, auger=False, hold=HOLD_NO_MEASUREMENT,
                                                 cart_valid=np.zeros(1201)))
    assert out["status"] == "stopped_safe"
    assert out["reason"].startswith("perception never found the cart: 0 of 1201 frames; the auger never started")
    assert out["cart_found_frames"] == 0 and out["perception_frames"] == 1201


def test_a_sensor_unfit_for_the_target_is_a_safe_stop_that_names_its_figure():
    """Perception withheld every height map because its cameras' expected error at the cart exceeds what the
    target allows: the outcome names that figure, not only the controller's hold."""
    why = "the cameras' expected error of a cell's height at the cart, 4.6 cm at 5.5 m, exceeds the 2.5 cm"
    summary = {**_summary([1.0] * 9), "perception": {"fitness": {"reason": why}}}
    out = judge(SC, summary, _series(n=101, auger=False, hold=HOLD_NO_MEASUREMENT))
    assert out["status"] == "stopped_safe" and out["reason"].startswith(why + "; 0 of 9 sections at target")
    plain = judge(SC, _summary([1.0] * 9), _series(n=101, auger=False, hold=HOLD_NO_MEASUREMENT))
    assert plain["reason"].startswith("no usable height map yet")


def test_a_controller_that_holds_says_why_and_with_what_confidence():
    out = judge(SC, _summary([TARGET] * 5 + [1.2] * 4), _series(hold=HOLD_LOST, sigma=0.062,
                                                                  cart_valid=np.r_[np.ones(300), np.zeros(301)]))
    assert out["status"] == "stopped_safe"
    assert "1-sigma reached 6.2 cm at 30.0 s: auger off, holding" in out["reason"]
    assert "5 of 9 sections at target (section 6 peaks 1.20 m of 1.90 m)" in out["reason"]


def test_a_false_done_and_a_silent_idle_controller_fail():
    short = [TARGET] * 8 + [1.5]
    assert "declared the cart full but only 8 of 9" in judge(SC, _summary(short), _series(all_full=True))["reason"]
    out = judge(SC, _summary([1.0] * 9), _series(auger=False))
    assert out["status"] == "job_failed" and "never started and the controller gave no reason" in out["reason"]
    # still running when the grain was not stopped: a hold only counts once the flow is off
    out = judge(SC, _summary(short), _series(hold=HOLD_LOST, flow_end=0.5))
    assert out["status"] == "job_failed" and "with the grain still flowing" in out["reason"]


@pytest.mark.parametrize("fraction, shown", [(0.873, "87.3 % filled"), (0.0415, "4.2 % filled"), (None, "")])
def test_a_run_its_duration_ended_at_work_is_unfinished_with_its_progress(fraction, shown):
    """Still filling when the duration ran out, nothing spilled or overfilled: unfinished, not failed, with the
    fill fraction and the sections at target."""
    short = [TARGET] * 6 + [1.5, 1.2, 1.1]
    fill = {"fill_fraction": fraction} if fraction is not None else {}
    summary = _summary(short)
    summary["fill"].update(fill)
    out = judge(SC, summary, _series(n=101, flow_end=1.0))
    assert out["status"] == "unfinished" and out["fill_fraction"] == fraction
    assert out["reason"] == (f"the run ended at its duration, 10.0 s, before the job was done: {shown}"
                             + (", " if shown else "") + "6 of 9 sections at target (section 9 peaks 1.10 m of 1.90 m)")
    # spill or overfill at the end of a short run is still a failed job
    assert judge(SC, _summary(short, spill_kg=3.0), _series(n=101, flow_end=1.0))["status"] == "job_failed"


def test_a_run_that_did_not_complete_fails_the_job_naming_why():
    out = judge(SC, _summary([TARGET] * 9, completed=False, error={"message": "dynamics crashed at frame 12"}), {})
    assert out["status"] == "job_failed" and "did not complete (failed after 60.0 s): dynamics crashed" in out["reason"]
    assert outcome_line(out).startswith("outcome: job_failed: the run did not complete")


def test_console_log_and_require_filled(tmp_path, capsys, shm_clean):
    args = ["run", "default", "--renderer", "none", "--feedback", "ground_truth", "--duration", "3", "--quiet"]
    assert main(args + ["--out", str(tmp_path / "a")]) == 0
    out = capsys.readouterr().out
    assert "outcome: unfinished: the run ended at its duration, 3.0 s, before the job was done: " in out
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert summary["outcome"]["status"] == "unfinished" and summary["completed"] is True
    assert f"{summary['fill']['fill_fraction'] * 100:.1f} % filled, 0 of 9 sections at target" in out
    assert "outcome: unfinished: the run ended at its duration" in (tmp_path / "a" / "log.txt").read_text()
    assert main(args + ["--out", str(tmp_path / "b"), "--require-filled"]) == EXIT_NOT_FILLED


def test_a_case_built_to_stop_safe_stops_safe_even_when_its_duration_ends_it(tmp_path, capsys, shm_clean):
    """grazing_sensor never sees into the cart: a run cut short by its duration is still stopped_safe with the
    reason, not unfinished (the auger never started), and the packaged description says so."""
    from cosim.scenario.loader import load_scenario, resolve_scenario_arg

    assert "built to stop safe" in load_scenario(resolve_scenario_arg("grazing_sensor")).description
    args = ["run", "grazing_sensor", "--renderer", "mock", "--duration", "1.5", "--quiet", "--set",
            "outputs.figures=false", "--set", "field.draw=[]", "--out", str(tmp_path / "g")]
    assert main(args) == 0
    summary = json.loads((tmp_path / "g" / "summary.json").read_text())
    assert summary["outcome"]["status"] == "stopped_safe"
    assert summary["outcome"]["reason"].startswith("perception never found the cart: 0 of 16 frames; the auger never")
