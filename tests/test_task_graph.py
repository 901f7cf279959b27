"""`TaskGraph`: keys named for their function, so that the scheduler's per-prefix
duration estimates tell a getitem from the task whose result it reads."""

import operator

import dask
from dask.utils import key_split

from volseg._task_graph import TaskGraph


def _pruned_leaf(values):
    return sum(values), list(values)


def test_keys_are_named_for_their_function_and_compute():
    graph = TaskGraph("test-prune")
    leaf = graph(_pruned_leaf, [1, 2, 3])
    first = graph.item(leaf, 0)
    rest = graph(operator.add, first, graph(len, graph.item(leaf, 1)))
    assert key_split(leaf) == "pruned_leaf-test-prune"
    assert key_split(first) == "getitem-test-prune"
    assert key_split(rest) == "add-test-prune"
    assert len({leaf, first, rest}) == 3
    assert dask.compute(*graph.delayed([leaf, first, rest])) == ((6, [1, 2, 3]), 6, 9)


def test_two_graphs_never_share_a_key():
    a, b = TaskGraph("same"), TaskGraph("same")
    assert a(len, [1]) != b(len, [1])
