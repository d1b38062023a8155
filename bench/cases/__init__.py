"""The named benchmark cases, one module per subject; each registers its cases with ``harness.case``
(``python bench/run.py --list``)."""
