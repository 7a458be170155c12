"""Jobs: what each flow does, written once for a plain run and a Prefect run (see flows/runner.py). No Prefect import here."""
