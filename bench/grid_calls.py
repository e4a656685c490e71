"""Times `dqskin.skin_many` as the add-on calls it on a grid like `blender_bench.py`'s: each
vertex on its 4 nearest of 64 bones, every bone turned, object and armature spaces that fold.
For comparing two builds of the module, processes alternated (docs/performance.md):

    .venv/bin/python bench/grid_calls.py --vertices 250000 --calls 400
    PYTHONPATH=other-build .venv/bin/python bench/grid_calls.py --vertices 250000 --calls 400
"""

import argparse
import time

import dqskin
import numpy as np


def grid_job(vertices: int, method: str) -> dqskin.SkinJob:
    side = max(2, round(vertices**0.5))
    xs = np.linspace(-4.0, 4.0, side, dtype=np.float32)
    co = np.stack(np.meshgrid(xs, xs), -1).reshape(-1, 2)
    positions = np.concatenate([co, np.zeros((len(co), 1), np.float32)], 1)
    heads = np.array([(-4 + 8 * (i + 0.5) / 8, -4 + 8 * (j + 0.5) / 8) for i in range(8) for j in range(8)], np.float32)
    d2 = ((co[:, None, :] - heads[None]) ** 2).sum(-1)
    nearest = np.argsort(d2, 1)[:, :4]
    weights = 1.0 / (np.take_along_axis(d2, nearest, 1) + 0.05)
    weights /= weights.sum(1, keepdims=True)
    influences = dqskin.Influences.from_dense(nearest.astype(np.uint32), weights.astype(np.float32), len(heads))
    rng = np.random.default_rng(1)
    deform = np.tile(np.eye(4, dtype=np.float32), (len(heads), 1, 1))
    for m in deform:
        axis = rng.normal(size=3)
        m[:3, :3] = rotation(axis / np.linalg.norm(axis), 1.0)
        m[:3, 3] = rng.normal(size=3) * 0.1
    rest = np.tile(np.eye(4, dtype=np.float32), (len(heads), 1, 1))
    premat = np.eye(4, dtype=np.float32)
    premat[:3, 3] = (0.5, -0.25, 1.0)
    postmat = np.linalg.inv(premat).astype(np.float32)
    return dqskin.SkinJob(positions, influences, deform, rest, method=method, premat=premat, postmat=postmat)


def rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' rotation matrix about a unit axis."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--vertices", type=int, default=250_000)
    parser.add_argument("--calls", type=int, default=400)
    parser.add_argument("--method", default="linear")
    args = parser.parse_args()
    if args.vertices < 4 or args.calls < 1:
        parser.error("--vertices must be at least 4 and --calls at least 1")
    job = grid_job(args.vertices, args.method)
    for _ in range(20):
        dqskin.skin_many([job])
    times = []
    for _ in range(args.calls):
        t = time.perf_counter()
        dqskin.skin_many([job])
        times.append(time.perf_counter() - t)
    print(
        f"{len(job.positions)} vertices, {args.method}: "
        f"median {1e3 * np.median(times):.3f} ms, tenth percentile {1e3 * np.percentile(times, 10):.3f} ms "
        f"({dqskin.__file__})"
    )


if __name__ == "__main__":
    main()
