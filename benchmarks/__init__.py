"""The benchmark scripts, run from the repository root as ``python -m benchmarks.<name>``: each prints a table and
writes JSON to ``benchmarks/results/``. They are scripts of the source tree, not shipped in the wheel."""
