"""validate: an answer made by Allocation.centralized is checked by its (row, column) hint,
with the same result and the same errors as the check by id (a wrong hint changes nothing)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from dispatch.api.problem import Allocation
from dispatch.decide.answers import validate
from dispatch.errors import AllocationError
from tests.allocators.helpers import make_problem, random_problem


def _without_hint(allocation: Allocation) -> Allocation:
    out = dataclasses.replace(allocation, index=())
    assert out == allocation
    return out


@pytest.mark.parametrize("seed", range(5))
def test_same_index_with_and_without_the_hint(seed):
    problem = random_problem(seed, 7, 5)
    rng = np.random.default_rng(seed)
    rows = rng.permutation(7)[:4].tolist()
    cols = rng.permutation(5)[:4].tolist()
    pairs = list(zip(rows, cols))
    answer = Allocation.centralized(problem, pairs)
    assert list(answer.index) == pairs
    assert validate(problem, answer) == validate(problem, _without_hint(answer)) == pairs
    # numpy integers as indices (an allocator's argmin) give the same
    np_answer = Allocation.centralized(problem, [(np.int64(a), np.int64(t)) for a, t in pairs])
    assert validate(problem, np_answer) == pairs


def test_a_bad_centralized_answer_gets_the_errors_of_the_full_check():
    problem = make_problem([[1.0, np.inf], [2.0, 3.0]])
    with pytest.raises(AllocationError, match="agent 100 is given more than one task"):
        validate(problem, Allocation.centralized(problem, [(0, 0), (0, 1)]))
    with pytest.raises(AllocationError, match="task 500 is given to more than one agent"):
        validate(problem, Allocation.centralized(problem, [(0, 0), (1, 0)]))
    with pytest.raises(AllocationError, match=r"agent 100 cannot serve task 501 \(infinite"):
        validate(problem, Allocation.centralized(problem, [(0, 1)]))
    # a negative index names the last agent, as the id it was turned into says
    assert validate(problem, Allocation.centralized(problem, [(-1, 1)])) == [(1, 1)]


def test_a_wrong_hint_is_not_believed():
    problem = make_problem([[1.0, 4.0], [2.0, 3.0]])
    answer = Allocation.centralized(problem, [(0, 1), (1, 0)])
    for wrong in (((1, 0), (0, 1)),  # rows and columns of other pairs
                  ((0, 1),),  # fewer than the pairs
                  ((0, 1), (5, 0))):  # out of range
        assert validate(problem, dataclasses.replace(answer, index=wrong)) == [(0, 1), (1, 0)]
