"""The benchmark scripts (``python benchmarks/<name>.py`` or ``python -m sb3_genrl.benchmarks.<name>``): each prints a
table and writes JSON to ``benchmarks/results/``."""
