"""serpar command line (``serpar`` / ``python -m serpar``); the physics lives in sim/ and friends."""

import sim  # noqa: F401  (sets the headless GL default before mujoco is imported)
