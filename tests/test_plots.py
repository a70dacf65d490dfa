"""The pose panels of the figures: box outlines as collections, the legend where the boxes are not."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from crosscert.verifier.plots import _pose_boxes, _pose_legend  # noqa: E402


@pytest.fixture
def axes():
    fig, a = plt.subplots()
    yield a
    plt.close(fig)


def _boxes(centres, half=0.002):
    c = np.asarray(centres, dtype=float)
    return c - half, c + half


def test_one_collection_per_run_of_one_colour_and_no_box_dropped(axes):
    lo, hi = _boxes([[0.01 * k, 0.02 * k] for k in range(10)])
    lo[4, 0] = np.inf  # not finite: not drawn
    colours = ["b", "b", "r", "r", "r", "b", "b", "b", "r", "r"]
    _pose_boxes(axes, lo, hi, 1, lambda k: colours[k])
    assert not axes.patches
    runs = axes.collections
    assert len(runs) == 4  # b b | r r (the third r not finite) | b b b | r r
    assert [len(c.get_paths()) for c in runs] == [2, 2, 3, 2]
    first = runs[0].get_paths()[1].vertices[:4]  # box 1 in mm, corners in order
    np.testing.assert_allclose(first, [[8, 18], [12, 18], [12, 22], [8, 22]])


@pytest.mark.parametrize("crowded, expected", [("upper right", "upper left"), ("upper left", "upper right"),
                                                ("none", "upper right")])
def test_the_legend_goes_to_a_corner_the_boxes_leave_free(axes, crowded, expected):
    centres = {"upper right": [[0.09, 0.09], [0.085, 0.095]], "upper left": [[0.01, 0.09], [0.015, 0.095]],
               "none": [[0.05, 0.05]]}[crowded]
    lo, hi = _boxes(centres)
    axes.plot([], [], label="pose box")
    axes.set_xlim(0, 100)
    axes.set_ylim(0, 100)
    _pose_legend(axes, [(lo, hi)])
    assert axes.get_legend()._loc == axes.get_legend().codes[expected]


def test_the_legend_avoids_the_drawn_path_too(axes):
    lo, hi = _boxes([[0.09, 0.09]])  # upper right taken by a box
    path = np.array([[0.01, 0.09], [0.02, 0.095]])  # upper left by the planned path
    axes.plot([], [], label="pose box")
    axes.set_xlim(0, 100)
    axes.set_ylim(0, 100)
    _pose_legend(axes, [(lo, hi)], [path])
    assert axes.get_legend()._loc == axes.get_legend().codes["lower left"]
