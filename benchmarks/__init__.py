"""Side-by-side benchmarks: ours against the reference library, in one process.

``python -m benchmarks [NAME ...]`` runs the named benchmarks (all by default), prints
median milliseconds of ours and of the reference, their ratio, and an accuracy figure for
each, and writes one JSON record per benchmark to ``benchmarks/results/``.
"""
