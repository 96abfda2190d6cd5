"""Fits every cloud of a directory with EMS (Liu et al., "Robust and Accurate
Superquadric Recovery: a Probabilistic Approach", CVPR 2022), by its released Python
implementation with its default settings, and writes DIR/fits.json in the form
`examples/superellipsoid_clouds.rs judge` reads.

    python3 scripts/ems_fits.py EMS_SRC DIR

EMS_SRC is the directory holding the `EMS` package (`Python/src` of
github.com/bmlklwx/EMS-superquadric_fitting; it needs numpy, scipy and numba, and on
numpy 1.24 or later its one `np.int(0)` read as `int(0)`). DIR holds the clouds, one
`<seed>.xyz` each (x y z a line), as `superellipsoid_clouds export` writes them. Each
fit is timed alone, after one fit that compiles EMS's numba functions.
"""

import json
import pathlib
import sys
import time

import numpy as np


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    sys.path.insert(0, sys.argv[1])
    from EMS.EMS_recovery import EMS_recovery

    clouds = sorted(pathlib.Path(sys.argv[2]).glob("*.xyz"), key=lambda p: int(p.stem))
    if not clouds:
        sys.exit(f"no <seed>.xyz clouds in {sys.argv[2]}")
    EMS_recovery(np.loadtxt(clouds[0]))  # (compiles the numba functions)
    fits = []
    for path in clouds:
        points = np.loadtxt(path)
        start = time.perf_counter()
        sq, _ = EMS_recovery(points)
        ms = 1e3 * (time.perf_counter() - start)
        eps1, eps2 = sq.shape
        fits.append(
            {
                "seed": int(path.stem),
                "shape": [*map(float, sq.scale), float(eps1), float(eps2)],
                "rotation": sq.RotM.tolist(),
                "translation": [*map(float, sq.translation)],
                "ms": ms,
            }
        )
    (pathlib.Path(sys.argv[2]) / "fits.json").write_text(json.dumps(fits))
    print(f"{len(fits)} clouds fitted; median {np.median([f['ms'] for f in fits]):.0f} ms")


if __name__ == "__main__":
    main()
