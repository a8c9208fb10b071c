"""Test configuration shared by the whole suite.

Hypothesis runs with a fixed profile so that every CI run draws the same examples and
nothing is read from or written to an example database (none lives in the repository):

* ``ci`` (default): derandomized, no database, no deadline;
* ``dev``: random exploration, for hunting new counterexamples locally
  (``HYPOTHESIS_PROFILE=dev python3 -m pytest tests``).
"""

from __future__ import annotations

import os

from hypothesis import HealthCheck, settings

settings.register_profile("ci", derandomize=True, database=None, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("dev", database=None, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
