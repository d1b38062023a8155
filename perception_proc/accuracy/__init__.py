"""Accuracy against truth: of the perception stage, of each sensor, and the standalone report."""
