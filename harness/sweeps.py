"""Parameter sweeps: the configurations of a filter over a grid of parameter values.

``--grid FILTER.PARAM=V1,V2,...`` (repeatable) gives a filter several values per parameter;
its configurations are the cartesian product of those values, each on top of the defaults,
the filter's preset and the single ``--param`` values. Each configuration becomes its own job
(its parameters are in the job's identity and on its rows), so a sweep runs, resumes and is
scored like any other run.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from typing import Any

#: configurations of one filter above which a sweep is refused (a typo such as 1,...,1000)
MAX_CONFIGURATIONS = 1000


def grid_points(owner: str, overrides: Mapping[str, Any],
                grid: Mapping[str, Sequence[Any]] | None = None) -> list[dict]:
    """The parameter overrides of every configuration of one filter: ``overrides`` plus one point of ``grid``.

    Parameters
    ----------
    owner : str
        The filter's name (for messages).
    overrides : mapping
        Single parameter values (``--param``).
    grid : mapping param -> list of values, optional
        Swept parameters (``--grid``); a parameter both in ``overrides`` and ``grid`` is an error.

    Returns
    -------
    list of dict
        One dict per point of the grid, in the order of the values given (the first parameter
        varies slowest); ``[overrides]`` without a grid. The planner checks each against the
        filter's declarations (:func:`harness.plan.filter_params`).

    Raises
    ------
    ValueError
        For an empty value list, a parameter both fixed and swept, or more than
        :data:`MAX_CONFIGURATIONS` points.
    """
    grid = {name: list(values) for name, values in (grid or {}).items()}
    both = sorted(set(grid) & set(overrides))
    if both:
        raise ValueError(f"filter {owner!r}: parameter(s) {both} given both by --param and --grid")
    empty = sorted(name for name, values in grid.items() if not values)
    if empty:
        raise ValueError(f"filter {owner!r}: --grid needs at least one value for {empty}")
    count = math.prod(len(values) for values in grid.values())
    if count > MAX_CONFIGURATIONS:
        raise ValueError(f"filter {owner!r}: the grid has {count} configurations, more than {MAX_CONFIGURATIONS}")
    names = list(grid)
    return [{**overrides, **dict(zip(names, values))} for values in itertools.product(*grid.values())]


__all__ = ["MAX_CONFIGURATIONS", "grid_points"]
