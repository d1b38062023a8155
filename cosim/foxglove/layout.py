"""The Foxglove layout for a run's panels, built with foxglove-sdk's layout types (``foxglove.layouts``).

``python -m cosim.foxglove.layout [--out FILE]`` writes it; the package ships the result as
``cosim/foxglove/layout.json`` (a test keeps the two equal). Left: a 3D panel in the ``world`` frame following
the cart, with the scene, the LiDAR cloud and the two height maps; right, top to bottom: the renderer's
depth-encoded image (:data:`IMAGE_TOPIC`), the auger position (desired and actual, m), the fullness of the cart's sections and the
perception's coverage and errors. Works live (``run --foxglove``) and on a recording (same topics; the
recording has no ``/scene``).
"""
from __future__ import annotations

import argparse
import sys

import foxglove.layouts as fl

__all__ = ["build_layout", "layout_json", "SECTIONS", "IMAGE_TOPIC", "main"]

#: cart sections plotted (the default scenario's nine)
SECTIONS = 9
#: the image panel's topic: the default scenario renderer's depth-encoded image block ``beams_depth``
IMAGE_TOPIC = "/beams/depth_encoded"


def _plot(title: str, paths: list[tuple[str, str]], y_label: str) -> fl.PlotPanel:
    return fl.PlotPanel(title=title, config=fl.PlotConfig(
        paths=[fl.PlotSeries(value=v, label=label, enabled=True, timestamp_method="receiveTime")
               for v, label in paths], show_legend=True, y_axis_label=y_label))


def build_layout() -> fl.Layout:
    """The layout (see the module docstring)."""
    three_d = fl.ThreeDeePanel(title="co-simulation (world frame)", config=fl.ThreeDeeConfig(
        follow_tf="cart", topics={
            "/scene": fl.BaseRendererSceneUpdateTopicSettings(visible=True),
            "/lidar/points": fl.BaseRendererPointCloudTopicSettings(visible=True),
            "/heightmap/truth": fl.BaseRendererGridTopicSettings(visible=False),
            "/heightmap/perceived": fl.BaseRendererGridTopicSettings(visible=True),
        }))
    image = fl.ImagePanel(title="renderer (depth-encoded)", config=fl.ImageConfig(
        image_mode=fl.ImageModeConfig(image_topic=IMAGE_TOPIC)))
    auger = _plot("auger x (m)", [("/dyn_state.desired_auger_x_m", "desired"),
                                  ("/dyn_state.actual_auger_x_m", "actual")], "m")
    fullness = _plot("section fullness", [(f"/dyn_state.section{k}_fullness", f"section {k}")
                                          for k in range(1, SECTIONS + 1)], "fraction of the section")
    perception = _plot("perception", [("/perc_state.coverage", "coverage"),
                                      ("/perc_state.heightmap_rmse_m", "height map RMSE (m)"),
                                      ("/perc_state.impact_error_m", "impact error (m)")], "")
    right = fl.SplitContainer(direction="column", items=[fl.SplitItem(proportion=1, content=p)
                                                          for p in (image, auger, fullness, perception)])
    return fl.Layout(content=fl.SplitContainer(direction="row", items=[
        fl.SplitItem(proportion=3, content=three_d), fl.SplitItem(proportion=2, content=right)]))


def layout_json() -> str:
    """The layout as the indented JSON text shipped in ``layout.json``."""
    import json

    return json.dumps(json.loads(build_layout().to_json()), indent=2, sort_keys=True) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m cosim.foxglove.layout", description=__doc__.splitlines()[0])
    p.add_argument("--out", help="file to write (default: stdout)")
    args = p.parse_args(argv)
    if args.out:
        with open(args.out, "w") as f:
            f.write(layout_json())
    else:
        sys.stdout.write(layout_json())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
