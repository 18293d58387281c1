"""The learners' shared target encoding (nlosplan.tasks.targets)."""

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.tasks.targets import encode_targets


def test_positions_pass_through_as_float64():
    y, names = encode_targets("loc", [[0.1, 0.2], [0.3, -0.4]], 2)
    assert names is None
    assert y.dtype == np.float64
    np.testing.assert_array_equal(y, [[0.1, 0.2], [0.3, -0.4]])


def test_labels_index_the_sorted_names_or_the_given_order():
    y, names = encode_targets("shape", ["b", "a", "b"], 3)
    assert names == ("a", "b")
    np.testing.assert_array_equal(y, [1, 0, 1])
    y, names = encode_targets("size", [8, 12, 8], 3, classes=("12", "8", "4"))
    assert names == ("12", "8", "4")
    np.testing.assert_array_equal(y, [1, 0, 1])


@pytest.mark.parametrize(
    "task, targets, n, classes, message",
    [
        ("loc", [[0.1, 0.2]], 2, None, "localization targets must be (N, 2), got (1, 2)"),
        ("shape", [["a"], ["b"]], 2, None, "class targets must be (N,), got (2, 1)"),
        ("shape", ["a", "z"], 2, ("a", "b"), "training labels z are not among the classes"),
        ("shape", ["a", "a"], 2, None, "classification needs at least 2 classes, got 1"),
    ],
)
def test_bad_targets_say_what_is_wrong(task, targets, n, classes, message):
    with pytest.raises(UserError) as err:
        encode_targets(task, targets, n, classes)
    assert str(err.value) == message
