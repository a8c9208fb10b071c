"""Test configuration shared by the whole suite.

Hypothesis runs with a fixed profile so that every CI run draws the same examples and
nothing is read from or written to an example database (none lives in the repository):

* ``ci`` (default): derandomized, no database, no deadline;
* ``dev``: random exploration, for hunting new counterexamples locally
  (``HYPOTHESIS_PROFILE=dev python3 -m pytest tests``).
"""

from __future__ import annotations

import os

import pytest
from hypothesis import HealthCheck, settings

settings.register_profile("ci", derandomize=True, database=None, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("dev", database=None, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


# ------------------------------------------------------------------ shared expensive objects
# Objects that several test modules build with the same settings are computed once per
# session here. They are read-only for the tests: a test that changes one of them builds its
# own instead.
@pytest.fixture(scope="session")
def e12_example():
    """E12, ``cm.models.load("khalil_affine_control")``, loaded once per session (read-only:
    a test that changes the example or its ``info`` loads its own)."""
    import casadi_cmpc as cm

    return cm.models.load("khalil_affine_control")


@pytest.fixture(scope="session")
def e12_quasi4_sets(e12_example):
    """E12 (``khalil_affine_control``) and its quasi 4-step robust controllable sets (Alg 6.7,
    §6.3.4) at eps = 0.05, at most 12 sets, the recursion stopped as soon as both initial
    states of Fig 6.15 lie in a set (coarse and fast; not the maximal sets).

    Returns
    -------
    tuple
        ``(example, sets)``: the loaded example and the
        :class:`~casadi_cmpc.control.quasi.QuasiSequence` ``P_0 = T, ..., P_M`` about its
        model, its terminal set and the whole W (robust). Shared by
        tests/mpc/test_quasi_mpc.py and tests/codegen/test_export_quasi.py; do not modify.
    """
    from casadi_cmpc.control.quasi import quasi_controllable_sets

    ex = e12_example
    seqs = quasi_controllable_sets(ex.model, ex.terminal, steps=4, eps=0.05, max_sets=12,
                                   until=ex.x0s)
    return ex, seqs
