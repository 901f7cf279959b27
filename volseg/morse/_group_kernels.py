"""Compiled sweep of a group of the tree of block groups (`_group_tree`): a group's
share of the elder-rule union-find, used by the in-memory grouped pruning and by the
distributed build alike; flat, checked arrays, no defaults."""

import numba
import numpy as np

from .._union_find import find_root


@numba.njit(cache=True, nogil=True)
def decide(x, y, node_cell, node_open, ev_item, ev_young, ev_x_elder, up_item, up_x, up_y):
    """One block group's share of the elder-rule union-find (`_group_tree`).

    Edges 0..n-1 between local nodes x[k] and y[k], sorted by increasing key, swept
    from the last (the highest saddle) down. node_cell[i] is node i's cell (a maximum
    id: lower is higher), node_open[i] whether the cell may have edges outside the
    group. A component is closed when none of its nodes is open: then it is the whole
    graph's component at that level too. An edge whose lower side is closed is an
    event of the whole graph: that side's highest maximum dies (its elder, the other
    side's highest, is found later from the events: `_kernels.elders`). Any other edge
    goes up, its nodes replaced by their representatives (`erep`): the highest node of
    a closed component, or the open node whose component absorbed it. Returns the
    counts of events and of edges up.
    """
    n = len(node_cell)
    parent = np.arange(n)
    is_open = node_open.copy()
    eparent = np.arange(n)
    erep = np.arange(n)
    n_ev = n_up = 0
    for k in range(len(x) - 1, -1, -1):
        rx = find_root(parent, x[k])
        ry = find_root(parent, y[k])
        if rx == ry:
            continue
        x_higher = node_cell[rx] < node_cell[ry]
        high, low = (rx, ry) if x_higher else (ry, rx)
        high_end, low_end = (x[k], y[k]) if x_higher else (y[k], x[k])
        if not is_open[low]:               # the lower side is closed: its highest dies
            ev_item[n_ev] = k
            ev_x_elder[n_ev] = x_higher
            ev_young[n_ev] = node_cell[low]
            n_ev += 1
            parent[low] = high
            e = find_root(eparent, high_end)
            eparent[find_root(eparent, low_end)] = e
            if not is_open[high]:          # two closed components: one, the higher's
                erep[e] = high
            continue
        # undecided: the open side's component may be higher, or joined already, outside
        up_item[n_up] = k
        up_x[n_up] = erep[find_root(eparent, x[k])]
        up_y[n_up] = erep[find_root(eparent, y[k])]
        n_up += 1
        parent[low] = high
        is_open[high] = True
    return n_ev, n_up
