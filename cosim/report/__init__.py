"""Figures and reports from run directories: the paper's Figs 7-10 and the comparison report."""
from .figures import fig_auger, fig_fullness, fig_heightmaps, fig_profile, write_run_figures
from .rundata import RunData, load_run

__all__ = ["fig_auger", "fig_fullness", "fig_heightmaps", "fig_profile", "write_run_figures", "RunData", "load_run"]
