"""Many runs: sweeps on Dask (sweepfile, sweep, results, figures, commands), the fidelity study (study) and
the ground-truth-against-perception comparison (compare)."""
