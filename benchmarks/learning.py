"""Learning: fit + predict on digits, ours vs scikit-learn (single-threaded), and
DBSCAN on a million 3-D points in bounded memory."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import numpy as np

from benchmarks._harness import Record, paired_ms

_DBSCAN_1M = """
import resource, time, numpy as np
from robopercept.learning import DBSCAN
gen = np.random.default_rng(0)
centres = gen.uniform(0, 10, size=(50, 3))
X = centres[gen.integers(0, 50, 1_000_000)] + gen.normal(scale=0.15, size=(1_000_000, 3))
t = time.perf_counter()
db = DBSCAN(eps=0.05, min_samples=10).fit(X)
print(time.perf_counter() - t, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20,
      db.n_clusters_, int((db.labels_ == -1).sum()))
"""


def run(repeats: int) -> tuple[list[Record], dict]:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    from sklearn import cluster, decomposition, discriminant_analysis, ensemble, svm, tree
    from sklearn.datasets import load_digits
    from sklearn.metrics import adjusted_rand_score
    from threadpoolctl import threadpool_limits

    from robopercept import learning as L

    X, y = load_digits(return_X_y=True)
    Xc = X[:, X.std(axis=0) > 0]  # sklearn's eigen LDA needs a regular S_W
    cases = [
        ("kmeans", "k=10, k-means++, n_init=1",
         lambda: L.KMeans(10, random_state=0).fit(X).predict(X),
         lambda: cluster.KMeans(10, n_init=1, random_state=0).fit(X).predict(X), 1.5, repeats),
        ("dbscan", "eps=20.5, min_samples=5", lambda: L.DBSCAN(20.5).fit(X),
         lambda: cluster.DBSCAN(eps=20.5).fit(X), 1.5, repeats),
        ("pca", "10 components", lambda: L.PCA(10).fit(X).transform(X),
         lambda: decomposition.PCA(10, svd_solver="full").fit(X).transform(X), 1.5, repeats),
        ("lda", "eigen, 61 non-constant pixels", lambda: L.LDA().fit(Xc, y).predict(Xc),
         lambda: discriminant_analysis.LinearDiscriminantAnalysis(solver="eigen")
         .fit(Xc, y).predict(Xc), 1.5, repeats),
        ("meanshift", "bandwidth 25, every sample a seed", lambda: L.MeanShift(25).fit(X),
         lambda: cluster.MeanShift(bandwidth=25).fit(X), 1.0, 1),
        ("decision_tree", "gini, unpruned",
         lambda: L.DecisionTreeClassifier(random_state=0).fit(X, y).predict(X),
         lambda: tree.DecisionTreeClassifier(random_state=0).fit(X, y).predict(X),
         2.0, repeats),
        ("random_forest", "100 trees, sqrt features, 1 thread",
         lambda: L.RandomForestClassifier(100, random_state=0).fit(X, y).predict(X),
         lambda: ensemble.RandomForestClassifier(100, random_state=0).fit(X, y).predict(X),
         2.0, min(repeats, 5)),
        ("random_forest", "100 trees, ours on 2 threads",
         lambda: L.RandomForestClassifier(100, random_state=0, n_jobs=2).fit(X, y).predict(X),
         lambda: ensemble.RandomForestClassifier(100, random_state=0).fit(X, y).predict(X),
         None, min(repeats, 5)),
        ("svc_rbf", "C=1, gamma=scale, one-vs-one", lambda: L.SVC().fit(X, y).predict(X),
         lambda: svm.SVC().fit(X, y).predict(X), 2.0, min(repeats, 10)),
    ]  # fmt: skip
    records = []
    with threadpool_limits(1):
        for name, case, ours, ref, target, reps in cases:
            o = ours()
            r = ref()
            if name in ("kmeans", "dbscan", "meanshift"):
                lo = o if isinstance(o, np.ndarray) else o.labels_
                lr = r if isinstance(r, np.ndarray) else r.labels_
                acc, val = "adjusted Rand index vs sklearn", adjusted_rand_score(lr, lo)
            elif name == "pca":
                acc = "max |projection difference|"
                val = float(np.abs(np.abs(o) - np.abs(r)).max())
            else:
                acc, val = "training accuracy (sklearn's in extra)", float(np.mean(o == y))
                extra_ref = float(np.mean(r == y))
            ours_ms, ref_ms = paired_ms(ours, ref, repeats=reps, warmup=1 if reps < 5 else 2)
            extra = {"reference_accuracy": extra_ref} if "training" in acc else {}
            records.append(
                Record(name, case, ours_ms, ref_ms, "scikit-learn", acc, val, target, extra)
            )
    t = time.perf_counter()
    out = subprocess.run(
        [sys.executable, "-c", _DBSCAN_1M], capture_output=True, text=True, check=True
    ).stdout.split()
    wall = time.perf_counter() - t
    seconds, peak_gib, n_clusters, noise = float(out[0]), float(out[1]), int(out[2]), int(out[3])
    records.append(
        Record("dbscan_1m", "1M 3-D points, eps=0.05, min_samples=10", seconds * 1e3,
               float("nan"), "none (sklearn holds every neighbourhood)",
               "peak RSS GiB (limit 4)", peak_gib, None,
               {"clusters": n_clusters, "noise": noise, "process_wall_s": wall})
    )  # fmt: skip
    settings = {"data": "sklearn digits 1797 x 64", "threads": "sklearn 1 (threadpoolctl)"}
    return records, settings
