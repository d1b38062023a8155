"""Many runs: the fidelity study and the ground-truth-against-perception comparison."""
