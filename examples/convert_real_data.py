"""Convert excerpts of two measured data sets into marine_envs recordings.

Run by hand from the repository root (tests never run it; they read only its outputs)::

    python examples/convert_real_data.py                 # both data sets
    python examples/convert_real_data.py --only kvlcc2   # one of them
    python examples/convert_real_data.py --dry-run       # analyse and print, write nothing

It reads the originals in ``../shared/data`` (outside the package: the project never reads them
at run or test time) and writes into ``marine_envs/data/real/``:

``kvlcc2_roll_decay.csv`` (+ ``.json`` sidecar), model ``usv``
    SSPA roll-decay test 21338 of the KVLCC2 model M5057-01-A (scale 1:68), MIT,
    (c) 2020 Martin Alexandersson. Cut at the release (largest |phi|), the mean of the tail
    removed, low-pass filtered and decimated from 100 Hz to 10 Hz. Columns time, delta (= 0, no
    rudder), phi. The sidecar's ``params`` hold wn and zeta from the logarithmic decrement of the
    first three periods (model scale).

``hovercraft_epfl_<run>.csv`` (+ sidecars), model ``hovercraft``
    Two system-identification runs of a small indoor hovercraft (EPFL, MIT, (c) 2019 Mauro
    Pfister) on the 10 Hz time base of the thrust commands: inputs sigma_1, sigma_2 (the on/off
    thrust commands; frame and mapping in ``real_data/hovercraft_epfl.py``) and delta = 0;
    measured north, east, psi from the motion capture (glitches removed, yaw unwrapped, low-pass
    filtered and resampled). ``hovercraft_epfl_params.json`` holds lab-scale parameter overrides
    for the LCAC-type model, fitted by equation error to both runs.

The conversions live in ``real_data/`` next to this script: ``real_data/kvlcc2.py`` and
``real_data/hovercraft_epfl.py`` (the hovercraft's frame and thruster mapping is explained there).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from real_data.common import REPO
from real_data.hovercraft_epfl import convert_hovercraft
from real_data.kvlcc2 import convert_kvlcc2

DEFAULT_SOURCE = REPO.parent / "shared" / "data"
DEFAULT_OUT = REPO / "marine_envs" / "data" / "real"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=("Convert excerpts of the measured KVLCC2 roll-decay and EPFL hovercraft "
                     "data (../shared/data) into marine_envs recordings in "
                     "marine_envs/data/real/. Run by hand; prints the estimates."),
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--source", type=Path, default=DEFAULT_SOURCE,
                        help="folder holding roll_decay_kvlcc2/ and hovercraft_epfl/")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output folder")
    parser.add_argument("--only", choices=("kvlcc2", "hovercraft"),
                        help="convert only one data set")
    parser.add_argument("--dry-run", action="store_true",
                        help="analyse and print, write nothing")
    args = parser.parse_args(argv)
    if not args.source.is_dir():
        parser.error(f"source folder not found: {args.source}")
    sys.path.insert(0, str(REPO))  # run from a checkout without installing
    if args.only in (None, "kvlcc2"):
        convert_kvlcc2(args.source, args.out, args.dry_run)
    if args.only in (None, "hovercraft"):
        convert_hovercraft(args.source, args.out, args.dry_run)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
