#!/usr/bin/env python3
"""The peer of `levelmap bench-incremental`: GTSAM's ISAM2 replaying a 2D g2o pose graph node
by node, as a robot would add it, and measured the same way.

Each node is one ISAM2 update: the node (first guess: the estimate of the node it is linked
from, moved by the edge's measurement) and every edge whose newer end it is; the time of an
update is `update()` and the newest node's estimate (`calculateEstimatePose2`). Every
`--check-every` nodes the newest node's estimate is compared with a batch solve of the graph
so far (GTSAM's Levenberg-Marquardt from LAGO's start, GTSAM's own residual, so the peer is
scored against its own optimum). Node 0 is held by a prior of σ 1e-6.
ISAM2 factors by QR here (`--factorization`): with its default, Cholesky, it stops on manhattan
at node 727 ("indeterminate linear system" near node 695: that closure's information matrix is
nearly singular).

Prints one JSON object: per-update p50/p99/mean/max (ms), the newest node against the batch
(p50, max, share within 1 cm), and the final χ² (GTSAM's convention, 2 × error) against the
batch's.

Usage (the peers' venv, `../shared/peers/setup_venv.sh DIR`):
    DIR/bin/python scripts/isam2-replay.py GRAPH.g2o [--rate 100] [--check-every 500]
        [--relinearize-threshold 0.1] [--relinearize-skip 10] [--factorization QR|CHOLESKY]
"""
import argparse
import importlib.metadata
import json
import math
import time

import gtsam
import numpy as np


def read_g2o(path):
    edges = []
    with open(path) as f:
        for line in f:
            tok = line.split()
            if tok and tok[0] == "EDGE_SE2":
                i, j = int(tok[1]), int(tok[2])
                z = [float(v) for v in tok[3:6]]
                a = [float(v) for v in tok[6:12]]
                w = np.array([[a[0], a[1], a[2]], [a[1], a[3], a[4]], [a[2], a[4], a[5]]])
                noise = gtsam.noiseModel.Gaussian.Information(w)
                diagonal = gtsam.noiseModel.Diagonal.Precisions(np.diag(w))
                edges.append((i, j, gtsam.Pose2(*z), noise, diagonal))
    return edges


def percentile(sorted_values, q):
    return sorted_values[round((len(sorted_values) - 1) * q)]


def lago_start(diagonal):
    """LAGO's start (it takes diagonal noise only: the edges' information diagonals)."""
    return gtsam.lago.initialize(diagonal)


def batch_newest(graph, diagonal):
    initial = lago_start(diagonal)
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-9)
    params.setAbsoluteErrorTol(1e-12)
    params.setMaxIterations(200)
    result = gtsam.LevenbergMarquardtOptimizer(graph, initial, params).optimize()
    return result, 2.0 * graph.error(result)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("file")
    parser.add_argument("--rate", type=float, default=0.0)
    parser.add_argument("--check-every", type=int, default=500)
    parser.add_argument("--relinearize-threshold", type=float, default=0.1)
    parser.add_argument("--relinearize-skip", type=int, default=10)
    parser.add_argument("--factorization", default="QR", choices=["QR", "CHOLESKY"])
    args = parser.parse_args()

    edges = read_g2o(args.file)
    n = 1 + max(max(e[0], e[1]) for e in edges)
    brought = [[] for _ in range(n)]
    for e in edges:
        brought[max(e[0], e[1])].append(e)

    params = gtsam.ISAM2Params()
    params.setRelinearizeThreshold(args.relinearize_threshold)
    params.relinearizeSkip = args.relinearize_skip
    params.setFactorization(args.factorization)
    isam = gtsam.ISAM2(params)
    whole = gtsam.NonlinearFactorGraph()
    prior = gtsam.PriorFactorPose2(0, gtsam.Pose2(), gtsam.noiseModel.Isotropic.Sigma(3, 1e-6))
    whole.add(prior)
    whole_diagonal = gtsam.NonlinearFactorGraph()
    whole_diagonal.add(prior)
    first = gtsam.NonlinearFactorGraph()
    first.add(prior)
    values = gtsam.Values()
    values.insert(0, gtsam.Pose2())
    isam.update(first, values)

    estimates = {0: gtsam.Pose2()}
    times_ms, newest_off = [], []
    started = time.perf_counter()
    for k in range(1, n):
        if args.rate > 0:
            due = started + k / args.rate
            pause = due - time.perf_counter()
            if pause > 0:
                time.sleep(pause)
        factors = gtsam.NonlinearFactorGraph()
        guess = None
        for i, j, z, noise, diagonal in brought[k]:
            factors.add(gtsam.BetweenFactorPose2(i, j, z, noise))
            whole.add(gtsam.BetweenFactorPose2(i, j, z, noise))
            whole_diagonal.add(gtsam.BetweenFactorPose2(i, j, z, diagonal))
            if guess is None and j == k and i < k:
                guess = estimates[i].compose(z)
            elif guess is None and i == k and j < k:
                guess = estimates[j].compose(z.inverse())
        values = gtsam.Values()
        values.insert(k, guess if guess is not None else estimates[k - 1])
        t = time.perf_counter()
        isam.update(factors, values)
        estimate = isam.calculateEstimatePose2(k)
        times_ms.append((time.perf_counter() - t) * 1e3)
        estimates[k] = estimate
        size = k + 1
        if size % args.check_every == 0 or size == n:
            batch, _ = batch_newest(whole, whole_diagonal)
            reference = batch.atPose2(k)
            newest_off.append(math.hypot(estimate.x() - reference.x(), estimate.y() - reference.y()))
    final = isam.calculateEstimate()
    _, batch_chi2 = batch_newest(whole, whole_diagonal)
    times = sorted(times_ms)
    off = sorted(newest_off)
    print(json.dumps({
        "tool": "gtsam ISAM2 " + importlib.metadata.version("gtsam"),
        "file": args.file,
        "nodes": n,
        "edges": len(edges),
        "rate": args.rate,
        "relinearize_threshold": args.relinearize_threshold,
        "relinearize_skip": args.relinearize_skip,
        "factorization": args.factorization,
        "per_update_p50_ms": percentile(times, 0.5),
        "per_update_p99_ms": percentile(times, 0.99),
        "per_update_mean_ms": sum(times) / len(times),
        "per_update_max_ms": times[-1],
        "newest_vs_batch_p50_m": percentile(off, 0.5),
        "newest_vs_batch_max_m": off[-1],
        "newest_within_1cm": sum(1 for d in off if d <= 0.01) / len(off),
        "checks": len(off),
        "final_chi2": 2.0 * whole.error(final),
        "batch_chi2": batch_chi2,
    }, indent=2))


if __name__ == "__main__":
    main()
