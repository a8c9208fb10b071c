import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc._validate import as_boxes


def test_box_basic_properties():
    B = cm.Box([-1, 0], [1, 2])
    assert B.dim == 2
    np.testing.assert_array_equal(B.as_array(), [[-1, 1], [0, 2]])
    np.testing.assert_array_equal(B.mid, [0, 1])
    np.testing.assert_array_equal(B.rad, [1, 1])
    assert B.volume() == 4.0
    assert B.contains([0.5, 1.5]) is True
    assert B.contains([1.5, 1.5]) is False
    np.testing.assert_array_equal(B.contains([[0, 0], [2, 0]]), [True, False])
    assert {tuple(v) for v in B.vertices()} == {(-1, 0), (1, 0), (-1, 2), (1, 2)}


def test_box_refuses_bad_bounds():
    with pytest.raises(cm.EmptySetError, match="lo\\[1\\]"):
        cm.Box([0, 2], [1, 1])
    with pytest.raises(cm.InvalidBoundsError, match="NaN"):
        cm.Box([0, np.nan], [1, 1])
    with pytest.raises(cm.DimensionError, match="differ in length"):
        cm.Box([0, 0], [1])


def test_box_allows_infinite_target_but_not_sampling():
    B = cm.Box([0.0], [np.inf])
    assert not B.is_bounded()
    assert B.contains([1e300]) is True
    with pytest.raises(ValueError, match="unbounded"):
        B.sample(3)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(st.floats(-1e6, 1e6), st.floats(0, 1e3)), min_size=1, max_size=4),
       st.integers(0, 2 ** 31))
def test_samples_lie_inside(bounds, seed):
    lo = np.array([b[0] for b in bounds])
    hi = lo + np.array([b[1] for b in bounds])
    B = cm.Box(lo, hi)
    assert B.contains(B.sample(20, seed)).all()


def test_as_boxes_normaliser():
    assert as_boxes(cm.Box([0], [1])).shape == (1, 1, 2)
    assert as_boxes(np.zeros((3, 2, 2)), d=2).shape == (3, 2, 2)
    with pytest.raises(cm.DimensionError, match="expected 3 instead of 2"):
        as_boxes(np.zeros((3, 2, 2)), d=3, name="X")
    with pytest.raises(cm.EmptySetError, match="X is empty"):
        as_boxes(np.array([[1.0, 0.0]]), name="X")
    with pytest.raises(cm.InvalidBoundsError):
        as_boxes(np.array([[np.nan, 0.0]]))
    with pytest.raises(cm.DimensionError, match="shape"):
        as_boxes(np.zeros(3))


@pytest.mark.parametrize("lo, hi", [(["0", "a"], [1, 2]), (["0", "1"], ["1", "2"]),
                                    ([0, 1], np.array(["1", "2"])), ("0", "1"),
                                    ([0, np.str_("1")], [1, 2])])
def test_box_refuses_strings_and_names_the_argument(lo, hi):
    with pytest.raises(cm.InvalidBoundsError, match=r"Box (lo|hi) must be numbers"):
        cm.Box(lo, hi)
    with pytest.raises(ValueError):  # still a ValueError, as numpy's message was
        cm.Box(lo, hi)


def test_box_from_one_array_says_how_to_build_it():
    arr = np.array([[0.0, 1.0], [2.0, 3.0]])
    with pytest.raises(TypeError, match=r"Box\.from_array\(arr\).*Box\(\*arr\.T\)"):
        cm.Box(arr)
    B = cm.Box.from_array(arr)
    assert B == cm.Box(*arr.T)
    np.testing.assert_array_equal(B.as_array(), arr)
    with pytest.raises(cm.InvalidBoundsError, match="must be numbers"):
        cm.Box.from_array([["0", "1"]])


@pytest.mark.parametrize("content", [b"hello", b"", b"\x93NUMPY\x01\x00"])
def test_box_load_of_a_non_archive_names_file_and_format(tmp_path, content):
    path = tmp_path / "junk.npz"
    path.write_bytes(content)
    with pytest.raises(ValueError, match="junk.npz.*expected an .npz archive") as exc:
        cm.Box.load(path)
    assert "allow_pickle" not in str(exc.value) and "pickled" not in str(exc.value)
