"""Settings of the whole suite."""

import os

# no "compiling the <vehicle> kernels" note: tests that check stderr line by line would see it
# on a cold numba cache only (tests/test_first_use.py checks the note with this unset)
os.environ["MARINE_ENVS_QUIET"] = "1"

