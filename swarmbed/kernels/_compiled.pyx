# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""The kernels of :mod:`swarmbed.kernels.reference`, compiled: the same IEEE operations in the same
order (built with ``-ffp-contract=off``: no fused multiply-add), so the same bits; a test compares
the two on recorded and random calls."""

import numpy as np

from libc.math cimport ldexp, sqrt, isnan, INFINITY, NAN
from libc.stdlib cimport malloc, free

from swarmbed.kernels.reference import EXP_OVER as _OVER, EXP_UNDER as _UNDER
from swarmbed.kernels.reference import EXP_TAYLOR as _TAYLOR, INV_LN2 as _INV_LN2
from swarmbed.kernels.reference import LN2_HI as _LN2_HI, LN2_LO as _LN2_LO

# the reference's constants, taken from it so that the two cannot part
cdef double OVER = _OVER, UNDER = _UNDER, INV_LN2 = _INV_LN2, LN2_HI = _LN2_HI, LN2_LO = _LN2_LO
cdef double C[12]
for _n in range(12):
    C[_n] = _TAYLOR[_n]


cdef union _Bits:
    double d
    unsigned long long u


cdef inline double _exp(double x) noexcept nogil:
    cdef double t, k, r, q, p
    cdef long long n
    cdef _Bits scale
    if isnan(x):
        return NAN
    if x > OVER:
        return INFINITY
    if x < UNDER:
        return 0.0
    t = x * INV_LN2 + 0.5
    n = <long long>t  # floor(t), without a call: truncation, one less below zero
    if <double>n > t:
        n -= 1
    k = <double>n
    r = (x - k * LN2_HI) - k * LN2_LO
    q = C[11]
    q = q * r + C[10]
    q = q * r + C[9]
    q = q * r + C[8]
    q = q * r + C[7]
    q = q * r + C[6]
    q = q * r + C[5]
    q = q * r + C[4]
    q = q * r + C[3]
    q = q * r + C[2]
    q = q * r + C[1]
    q = q * r + C[0]
    p = 1.0 + (r + (r * r) * q)
    if -1021 <= n <= 1023:  # 2**n is a normal double: times it is exact, as ldexp
        scale.u = <unsigned long long>(n + 1023) << 52
        return p * scale.d
    return ldexp(p, <int>n)


cdef inline double _distance(double ax, double ay, double bx, double by) noexcept nogil:
    cdef double dx = ax - bx, dy = ay - by
    return sqrt(dx * dx + dy * dy)


def exp(x):
    """e**x, elementwise: :func:`swarmbed.kernels.reference.exp`."""
    a = np.ascontiguousarray(x, dtype=np.float64)
    out = np.empty_like(a)
    cdef const double[::1] src = a.reshape(-1)
    cdef double[::1] dst = out.reshape(-1)
    cdef Py_ssize_t i
    with nogil:
        for i in range(src.shape[0]):
            dst[i] = _exp(src[i])
    return out


def path_gains(double x0, double y0, double speed, double rate, double log_discount,
               const double[::1] cx, const double[::1] cy, const double[::1] cr,
               const double[::1] px, const double[::1] py, const double[::1] pr,
               const unsigned char[::1] at_end):
    """:func:`swarmbed.kernels.reference.path_gains`."""
    cdef Py_ssize_t nc = cx.shape[0], L = px.shape[0], c, n
    best_out = np.empty(nc, dtype=np.float64)
    where_out = np.empty(nc, dtype=np.int64)
    cdef double[::1] best = best_out
    cdef long long[::1] where = where_out
    cdef double *buf = <double *>malloc((5 * (L + 1) + 1) * sizeof(double))
    if buf == NULL:
        raise MemoryError()
    cdef double *nx = buf
    cdef double *ny = buf + (L + 1)
    cdef double *seg = buf + 2 * (L + 1)
    cdef double *finish = buf + 3 * (L + 1)
    cdef double *suffix = buf + 4 * (L + 1)
    cdef double acc, work, arrive, g, top, d0, d1, delay, cw
    cdef long long at
    try:
        with nogil:
            nx[0] = x0
            ny[0] = y0
            for n in range(L):
                nx[n + 1] = px[n]
                ny[n + 1] = py[n]
                seg[n] = _distance(nx[n + 1], ny[n + 1], nx[n], ny[n])
            finish[0] = 0.0
            acc = 0.0
            for n in range(L):
                work = pr[n] / rate
                acc = acc + (seg[n] / speed + work)
                arrive = acc - work
                finish[n + 1] = arrive + work
                suffix[n] = _exp(log_discount * arrive) * pr[n]  # disc, summed from the end below
            suffix[L] = 0.0
            if L:
                acc = suffix[L - 1]
                for n in range(L - 2, -1, -1):
                    acc = acc + suffix[n]
                    suffix[n] = acc
            for c in range(nc):
                cw = cr[c] / rate
                d0 = _distance(cx[c], cy[c], nx[0], ny[0])
                top = 0.0
                at = 0
                for n in range(L + 1):
                    if n < L:
                        d1 = _distance(cx[c], cy[c], nx[n + 1], ny[n + 1])
                        delay = ((d0 + d1) - seg[n]) / speed + cw
                    else:
                        delay = 0.0
                    g = _exp(log_discount * (finish[n] + d0 / speed)) * cr[c] + (
                        _exp(log_discount * delay) - 1.0
                    ) * suffix[n]
                    if n == 0 or g > top or (at_end[c] and n == L):
                        top = g
                        at = n
                    d0 = d1
                best[c] = top
                where[c] = at
    finally:
        free(buf)
    return best_out, where_out


def distance_gains(double x0, double y0, double speed, double log_discount,
                   const double[::1] cx, const double[::1] cy, const double[::1] cr):
    """:func:`swarmbed.kernels.reference.distance_gains`."""
    cdef Py_ssize_t nc = cx.shape[0], c
    out = np.empty(nc, dtype=np.float64)
    cdef double[::1] dst = out
    with nogil:
        for c in range(nc):
            dst[c] = _exp(log_discount * _distance(cx[c], cy[c], x0, y0) / speed) * cr[c]
    return out


cdef enum:
    LEAVE = 0
    UPDATE = 1
    RESET = 2
    NONE = -1


cdef inline bint _better(double y1, long long z1, double y2, long long z2) noexcept nogil:
    return y1 > y2 or (y1 == y2 and z1 < z2)


cdef inline int _table(long long i, long long k, long long zk, double yk, long long zi, double yi,
                       int cmp_m, int cmp_n) noexcept nogil:
    """plugins/consensus.table: receiver i's action on one task; cmp_m, cmp_n: how the sender's
    news of agents zk and zi compares with the receiver's (1 newer, -1 older, 0 neither)."""
    if zk == k:  # the sender thinks it wins
        if zi == i:
            return UPDATE if _better(yk, k, yi, i) else LEAVE  # 1
        if zi == k or zi == NONE:
            return UPDATE  # 2, 4
        return UPDATE if (cmp_n > 0 or _better(yk, k, yi, zi)) else LEAVE  # 3
    if zk == i:  # the sender thinks the receiver wins
        if zi == k:
            return RESET  # 6
        if zi != i and zi != NONE and cmp_n > 0:
            return RESET  # 7
        return LEAVE  # 5, 7, 8
    if zk == NONE:  # the sender thinks nobody wins
        if zi == k:
            return UPDATE  # 15
        if zi != i and zi != NONE and cmp_n > 0:
            return UPDATE  # 16
        return LEAVE  # 14, 16, 17
    if zi == i:  # a third agent m = zk
        return UPDATE if (cmp_m > 0 and _better(yk, zk, yi, i)) else LEAVE  # 9
    if zi == k:
        return UPDATE if cmp_m > 0 else RESET  # 10
    if zi == zk or zi == NONE:
        return UPDATE if cmp_m > 0 else LEAVE  # 11, 13
    if cmp_m > 0 and (cmp_n > 0 or _better(yk, zk, yi, zi)):  # 12: a fourth agent n = zi
        return UPDATE
    if cmp_n > 0 and cmp_m < 0:
        return RESET
    return LEAVE


cdef inline int _compare(const double[::1] mine, const double[::1] their, long long m, Py_ssize_t out) noexcept nogil:
    cdef Py_ssize_t at = m if 0 <= m < out else out
    return (their[at] > mine[at]) - (their[at] < mine[at])


def table_actions(long long i, long long k, const long long[::1] wk, const double[::1] bk,
                  const long long[::1] wi, const double[::1] bi, const double[::1] mine, const double[::1] their):
    """Table 1 on each task: 0 leave, 1 update (to the sender's belief), 2 reset; ``wk``, ``bk`` the
    sender's winners and bids, ``wi``, ``bi`` the receiver's, ``mine``, ``their`` both sides'
    timestamps over agent ids (the last entry for any id either holds none for). An entry the same
    on both sides is left; an update to nobody is a reset (plugins/consensus.py, ``_decide``)."""
    cdef Py_ssize_t n, tasks = wk.shape[0], out = mine.shape[0] - 1
    actions_out = np.zeros(tasks, dtype=np.int8)
    cdef signed char[::1] actions = actions_out
    cdef int action
    with nogil:
        for n in range(tasks):
            if wk[n] == wi[n] and bk[n] == bi[n]:
                continue
            action = _table(i, k, wk[n], bk[n], wi[n], bi[n],
                            _compare(mine, their, wk[n], out), _compare(mine, their, wi[n], out))
            if action == UPDATE and wk[n] == NONE:
                action = RESET
            actions[n] = action
    return actions_out


cdef _receive_tasks(long long i, long long k, dict z, dict y, list entries, bint delta, skip, within,
                    const double[::1] mine, const double[::1] their):
    """The task part of plugins/consensus.ConsensusState.receive, on its own maps: ``entries`` the
    message's (task, winner, bid) tuples, sorted by task and each task once; the tasks whose belief
    differs from ours (and, for a whole message, the ones we hold that it does not name), less those
    outside ``within`` (when given) or in ``skip``, in task order, each through Table 1; an update
    sets ``z`` and ``y`` to the sender's objects, a reset removes the task from both."""
    cdef dict theirs = {}
    cdef set differing = set()
    cdef set named
    cdef tuple entry
    cdef object t, zo, yo, got
    cdef long long zk, zi
    cdef double yk, yi
    cdef Py_ssize_t out = mine.shape[0] - 1
    cdef int action
    for entry in entries:
        t = entry[0]
        zo, yo = z.get(t), y.get(t)
        zi = NONE if zo is None else <long long>zo
        yi = 0.0 if yo is None else <double>yo
        if zi != <long long>entry[1] or yi != <double>entry[2]:
            theirs[t] = entry
            differing.add(t)
    if not delta:
        named = {entry[0] for entry in entries}
        for t in z:
            if t not in named:
                differing.add(t)
    if within is not None:
        differing = {t for t in differing if t in within and t in theirs}
    for t in sorted(differing):
        if t in skip:
            continue
        got = theirs.get(t)
        if got is None:
            zk, yk = NONE, 0.0
        else:
            zk, yk = <long long>got[1], <double>got[2]
        zo, yo = z.get(t), y.get(t)
        zi = NONE if zo is None else <long long>zo
        yi = 0.0 if yo is None else <double>yo
        if zk == zi and yk == yi:
            continue
        action = _table(i, k, zk, yk, zi, yi, _compare(mine, their, zk, out), _compare(mine, their, zi, out))
        if action == UPDATE and zk != NONE:
            z[t], y[t] = got[1], got[2]
        elif action != LEAVE:
            z.pop(t, None)
            y.pop(t, None)


def winners_changed(dict z, dict y, dict told):
    """plugins/consensus.winners_changed: the map task -> (winner, bid) of ``z`` and ``y``, in
    ``z``'s order, and the (task, winner, bid) entries that differ from ``told``'s (the last message's)."""
    cdef dict winners = {}
    cdef list changed = []
    cdef object t, w, b
    cdef tuple pair
    for t, w in z.items():
        b = y[t]
        pair = (w, b)
        winners[t] = pair
        if told.get(t) != pair:
            changed.append((t, w, b))
    return winners, changed


# -- packing a CBBA message's vectors (plugins/consensus.py: pack_rows / pack_columns on its keys) ----
from libc.math cimport floor
from libc.string cimport memcpy
from cpython.bytes cimport PyBytes_FromStringAndSize, PyBytes_AS_STRING


cdef inline void _put_int(char* at, long long value, int size) noexcept nogil:
    """``value``'s lowest ``size`` bytes, little-endian (two's complement: a cast that wraps)."""
    cdef unsigned long long u = <unsigned long long>value
    cdef int b
    for b in range(size):
        at[b] = <char>((u >> (8 * b)) & 0xFF)


cdef inline void _put_double(char* at, double value) noexcept nogil:
    cdef _Bits bits
    bits.d = value
    _put_int(at, <long long>bits.u, 8)


def pack_stamps(const long long[::1] agents, const double[::1] stamps):
    """``pack_columns((agents, stamps), STAMP_KEYS)``: the key of the narrowest layout that holds
    every (agent, stamp) exactly ('s' i1/u2, 'r' i2/u2, 'q' i2/i4, 'p' i2/f8) and the packed bytes;
    None where the Python must decide (no rows, a NaN stamp, an agent id beyond int16)."""
    cdef Py_ssize_t n = agents.shape[0], j
    cdef long long amin, amax
    cdef double smin, smax, v
    cdef bint whole = True
    cdef int agent_size, stamp_size, size
    cdef char* out
    if n == 0 or stamps.shape[0] != n:
        return None
    amin = amax = agents[0]
    smin = smax = stamps[0]
    for j in range(n):
        v = stamps[j]
        if isnan(v):
            return None
        if v != floor(v):
            whole = False
        if v < smin:
            smin = v
        if v > smax:
            smax = v
        if agents[j] < amin:
            amin = agents[j]
        if agents[j] > amax:
            amax = agents[j]
    if amin < -32768 or amax > 32767:
        return None
    if whole and -128 <= amin and amax <= 127 and 0 <= smin and smax <= 65535:
        key, agent_size, stamp_size = "s", 1, 2
    elif whole and 0 <= smin and smax <= 65535:
        key, agent_size, stamp_size = "r", 2, 2
    elif whole and -2147483648.0 <= smin and smax <= 2147483647.0:
        key, agent_size, stamp_size = "q", 2, 4
    else:
        key, agent_size, stamp_size = "p", 2, 8
    size = agent_size + stamp_size
    packed = PyBytes_FromStringAndSize(NULL, n * size)
    out = PyBytes_AS_STRING(packed)
    for j in range(n):
        _put_int(out + j * size, agents[j], agent_size)
        if stamp_size == 8:
            _put_double(out + j * size + agent_size, stamps[j])
        else:
            _put_int(out + j * size + agent_size, <long long>stamps[j], stamp_size)
    return key, packed


def pack_winners(list rows):
    """``pack_rows(rows, WINNER_KEYS)`` for (task, winner, bid) rows of Python ints and floats: the
    key of the narrowest layout ('w' u2/i1/f8, 'v' u2/i2/f8, 'u' u4/i2/f8) and the packed bytes;
    None where the Python must decide (no rows, another type, an id beyond the widest layout)."""
    cdef Py_ssize_t n = len(rows), j
    cdef long long tmin = 0, tmax = 0, wmin = 0, wmax = 0, t, w
    cdef int task_size, winner_size, size
    cdef char* out
    cdef tuple row
    if n == 0:
        return None
    tasks = np.empty(n, np.int64)
    winners = np.empty(n, np.int64)
    bids = np.empty(n, np.float64)
    cdef long long[::1] ts = tasks, ws = winners
    cdef double[::1] bs = bids
    for j in range(n):
        row = rows[j]
        if len(row) != 3 or type(row[0]) is not int or type(row[1]) is not int or type(row[2]) is not float:
            return None
        try:
            t, w = row[0], row[1]
        except OverflowError:
            return None
        ts[j], ws[j], bs[j] = t, w, row[2]
        if j == 0 or t < tmin:
            tmin = t
        if j == 0 or t > tmax:
            tmax = t
        if j == 0 or w < wmin:
            wmin = w
        if j == 0 or w > wmax:
            wmax = w
    if tmin < 0 or tmax > 4294967295 or wmin < -32768 or wmax > 32767:
        return None
    if tmax <= 65535 and -128 <= wmin and wmax <= 127:
        key, task_size, winner_size = "w", 2, 1
    elif tmax <= 65535:
        key, task_size, winner_size = "v", 2, 2
    else:
        key, task_size, winner_size = "u", 4, 2
    size = task_size + winner_size + 8
    packed = PyBytes_FromStringAndSize(NULL, n * size)
    out = PyBytes_AS_STRING(packed)
    for j in range(n):
        _put_int(out + j * size, ts[j], task_size)
        _put_int(out + j * size + task_size, ws[j], winner_size)
        _put_double(out + j * size + task_size + winner_size, bs[j])
    return key, packed


# -- a CBBA receive, timestamps and tasks (plugins/consensus.ConsensusState.receive) -----------------
#: the timestamp layouts of plugins/consensus.STAMP_KEYS, in its order: (agent bytes, stamp bytes,
#: stamp kind: 0 unsigned, 1 signed, 2 float64)
cdef int _STAMP_LAYOUTS[4][3]
_STAMP_LAYOUTS[0][:] = [1, 2, 0]
_STAMP_LAYOUTS[1][:] = [2, 2, 0]
_STAMP_LAYOUTS[2][:] = [2, 4, 1]
_STAMP_LAYOUTS[3][:] = [2, 8, 2]


cdef inline long long _get_int(const unsigned char* at, int size, bint signed) noexcept nogil:
    """The little-endian integer of ``size`` bytes at ``at``."""
    cdef unsigned long long u = 0
    cdef int b
    for b in range(size):
        u |= (<unsigned long long>at[b]) << (8 * b)
    if signed and size < 8 and (u >> (8 * size - 1)) & 1:
        u |= ~((1ULL << (8 * size)) - 1)
    return <long long>u


cdef inline double _get_double(const unsigned char* at) noexcept nogil:
    cdef _Bits bits
    bits.u = <unsigned long long>_get_int(at, 8, False)
    return bits.d


def receive(long long i, long long k, double now, double t, bint delta, const double[::1] stamps,
            raw, int layout, dict z, dict y, list entries, skip, within):
    """plugins/consensus.ConsensusState.receive after its checks: the sender's timestamps (``raw``
    packed in ``STAMP_KEYS[layout]``; no layout, or bytes that are not whole entries: none), both
    sides' timestamps over agent ids, ``_receive_tasks``, and the timestamps merged (a stamp
    replaces ours only where it is greater: NaN is no news). Returns the new timestamps array."""
    cdef Py_ssize_t n = 0, j, size = 0, known = stamps.shape[0], covered
    cdef long long top = k, a
    cdef const unsigned char* rows = NULL
    cdef int agent_size = 0, stamp_size = 0, kind = 0
    cdef double v
    if 0 <= layout < 4 and isinstance(raw, bytes):
        agent_size, stamp_size, kind = _STAMP_LAYOUTS[layout][0], _STAMP_LAYOUTS[layout][1], _STAMP_LAYOUTS[layout][2]
        size = agent_size + stamp_size
        if len(raw) % size == 0:
            n = len(raw) // size
            rows = <const unsigned char*>PyBytes_AS_STRING(raw)
    for j in range(n):
        a = _get_int(rows + j * size, agent_size, True)
        if a > top:
            top = a
    covered = known if top < known else top + 1
    if not 0 <= i < known:
        raise ValueError(f"agent {i} holds no timestamp of its own in an array of {known}")
    mine_out = np.empty(covered + 1)
    their_out = np.empty(covered + 1)
    cdef double[::1] mine = mine_out, their = their_out
    for j in range(covered + 1):
        mine[j] = stamps[j] if j < known else -INFINITY
    mine[i] = now
    for j in range(covered + 1):
        their[j] = mine[j] if delta else -INFINITY
    for j in range(n):
        a = _get_int(rows + j * size, agent_size, True)
        if a < 0:
            continue  # no agent has a negative id: no news
        if kind == 2:
            v = _get_double(rows + j * size + agent_size)
        else:
            v = <double>_get_int(rows + j * size + agent_size, stamp_size, kind == 1)
        their[a] = v
    their[k] = t
    their[covered] = -INFINITY
    mine[covered] = -INFINITY
    _receive_tasks(i, k, z, y, entries, delta, skip, within, mine_out, their_out)
    their[i] = -INFINITY  # never news of ourselves
    merged_out = np.empty(covered)
    cdef double[::1] merged = merged_out
    for j in range(covered):
        v = stamps[j] if j < known else -INFINITY
        merged[j] = their[j] if their[j] > v else v
    return merged_out


# -- CBBA's bundle building (plugins/cbba.py; reference.py has the Python) ----------------------------
def task_columns(list tasks):
    """reference.task_columns: the x, y and remaining fields of each task tuple, as float64 arrays."""
    cdef Py_ssize_t n = len(tasks), j
    cx_out, cy_out, cr_out = np.empty(n), np.empty(n), np.empty(n)
    cdef double[::1] cx = cx_out, cy = cy_out, cr = cr_out
    cdef object task  # a TaskInfo: a tuple's subclass
    for j in range(n):
        task = tasks[j]
        cx[j], cy[j], cr[j] = task[1], task[2], task[3]
    return cx_out, cy_out, cr_out


def best_bid(long long agent, list items, const double[::1] gains, dict z, dict y):
    """reference.best_bid: the first highest positive gain that beats the known winning bid, or -1."""
    cdef Py_ssize_t n, at = -1
    cdef double gain, best = -INFINITY, known
    cdef object got
    for n in range(len(items)):
        gain = gains[n]
        if not gain > 0 or not gain > best:
            continue
        got = y.get(items[n])
        known = 0.0 if got is None else <double>got
        if gain > known:
            best, at = gain, n
        elif gain == known:
            got = z.get(items[n])
            if got is None or agent < <long long>got:
                best, at = gain, n
    return at if best < INFINITY and best > -INFINITY else -1
