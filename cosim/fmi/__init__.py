"""FMUs in the loop (FMI 2.0 co-simulation through fmpy): description, mapping checks, stepping. docs/fmu.md."""
