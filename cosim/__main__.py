"""``python -m cosim ...`` - same as ``python launch.py ...``."""
if __name__ == "__main__":
    from cosim.entry import exit_cli

    exit_cli()
