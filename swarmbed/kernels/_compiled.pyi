# The compiled kernels' signatures (_compiled.pyx), for type checkers: each is its Python
# reference's (reference.py, plugins/consensus.py).
from collections.abc import Collection

import numpy as np

def exp(x: np.ndarray | float) -> np.ndarray: ...
def path_gains(
    x0: float,
    y0: float,
    speed: float,
    rate: float,
    log_discount: float,
    cx: np.ndarray,
    cy: np.ndarray,
    cr: np.ndarray,
    px: np.ndarray,
    py: np.ndarray,
    pr: np.ndarray,
    at_end: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]: ...
def distance_gains(
    x0: float, y0: float, speed: float, log_discount: float, cx: np.ndarray, cy: np.ndarray, cr: np.ndarray
) -> np.ndarray: ...
def table_actions(
    i: int, k: int, wk: np.ndarray, bk: np.ndarray, wi: np.ndarray, bi: np.ndarray, mine: np.ndarray, their: np.ndarray
) -> np.ndarray: ...
def winners_changed(
    z: dict[int, int], y: dict[int, float], told: dict[int, tuple[int, float]]
) -> tuple[dict[int, tuple[int, float]], list[tuple[int, int, float]]]: ...
def pack_stamps(agents: np.ndarray, stamps: np.ndarray) -> tuple[str, bytes] | None: ...
def pack_winners(rows: list[tuple[int, int, float]]) -> tuple[str, bytes] | None: ...
def receive(
    i: int,
    k: int,
    now: float,
    t: float,
    delta: bool,
    stamps: np.ndarray,
    raw: object,
    layout: int,
    z: dict[int, int],
    y: dict[int, float],
    entries: list[tuple],
    skip: Collection[int],
    within: Collection[int] | None,
) -> np.ndarray: ...
def task_columns(tasks: list[tuple]) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...
def best_bid(agent: int, items: list[int], gains: np.ndarray, z: dict[int, int], y: dict[int, float]) -> int: ...
