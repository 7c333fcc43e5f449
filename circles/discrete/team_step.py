"""A discrete step's stages on a CPU's threads as one team (`team_step`, `circles.team`)."""
import taichi as ti

from .. import launch
from ..geometry import cells_in
from ..grid import (CPU_GROUP, _scan_shape, chunk_ends, chunk_starts, chunk_total, count_part, count_parts,
                    count_strays, owned_starts, scatter_group)
from ..team import STAGES, chunks_of, clear, loop_iterations, member_of, span, stage, value_slot
from .contacts import LIST0, LIST1, NLARGE, ROUND, WALLED, _keep_moved, _moved, _scan_large, _scan_slot
from .rounds import _first_pick_part, _first_resolve_part, _pick_item, _resolve_item, _wall

ndarr = ti.types.ndarray(ndim=1)


#: Items per chunk of a team step's stages (`team_step`): slots of the overlap search and the
#: scatter, and entries of a round's work list or of the walls' list.
TEAM_SLOTS = 2048
TEAM_LIST = 64


@ti.func
def _team_move(c, a: ti.template()):
    count_part(c, a[0][0].shape[0], _moved, _keep_moved, *a)


@ti.func
def _team_strays(c, a: ti.template()):
    count_strays(a[0].shape[0], *a)


@ti.func
def _team_totals(c, a: ti.template()):
    chunk_total(c, *a)


@ti.func
def _team_ends(c, a: ti.template()):
    chunk_ends(*a)
    a[0][0] = 0


@ti.func
def _team_starts(c, a: ti.template()):
    chunk_starts(c, *a)


@ti.func
def _team_scatter(c, a: ti.template()):
    g = ti.static(CPU_GROUP)
    lo, hi = span(c, chunks_of(a[0].shape[0], g), TEAM_SLOTS // g)
    for q in range(lo, hi):
        scatter_group(q, *a)


@ti.func
def _team_scan(c, a: ti.template()):
    lo, hi = span(c, a[0].shape[0], TEAM_SLOTS)
    for own in range(lo, hi):
        _scan_slot(own, *a)


@ti.func
def _team_scan_large(c, a: ti.template()):
    lo, hi = span(c, a[6][NLARGE], TEAM_LIST)
    for k in range(lo, hi):
        _scan_large(k, *a)


@ti.func
def _team_first_pick(c, a: ti.template()):
    _first_pick_part(c, *a)


@ti.func
def _team_first_resolve(c, a: ti.template()):
    _first_resolve_part(c, *a)


@ti.func
def _team_pick(c, a: ti.template()):
    lo, hi = span(c, a[0], TEAM_LIST)
    for q in range(lo, hi):
        _pick_item(q, *a[1:])


@ti.func
def _team_resolve(c, a: ti.template()):
    lo, hi = span(c, a[0], TEAM_LIST)
    for q in range(lo, hi):
        _resolve_item(q, *a[1:])


@ti.func
def _team_next_round(c, a: ti.template()):
    """The statements between rounds (`_resolve`'s last), and the length of the next round's
    list kept in the team's values for its stages' counts (the list's own counter changes
    within the next round)."""
    work, sync, side, r = ti.static(a)
    work[ROUND] += 1
    work[LIST0 + side] = 0
    sync[value_slot(r + 1)] = work[LIST0 + 1 - side]


@ti.func
def _team_walls(c, a: ti.template()):
    walled, work, pos, vel, radius, inv_mass, wall_count, wall_impulse, box_w, box_h, real, uniform = ti.static(a)
    lo, hi = span(c, work[WALLED], TEAM_LIST)
    if work[LIST0] == 0:  # the rounds settled
        for k in range(lo, hi):
            box = ti.Vector([box_w, box_h], dt=real)
            _wall(walled[k], pos, vel, radius, inv_mass, wall_count, wall_impulse, box, uniform)


@launch.kernel
def team_step(pos: ndarr, vel: ndarr, radius: ndarr, inv_mass: ndarr, ids: ndarr, partner: ndarr, picked: ndarr,
              marked: ndarr, contacts: ti.types.ndarray(ndim=2), n_contacts: ndarr,
              lists: ti.types.ndarray(ndim=2), work: ndarr, pair_count: ndarr, virial: ndarr, wall_count: ndarr,
              wall_impulse: ndarr, walled: ndarr, cell_of: ndarr, slot: ndarr, cell_count: ndarr, cell_start: ndarr,
              sorted_ids: ndarr, ncx: ti.i32, ncy: ti.i32, inv_cw: ti.f64, inv_ch: ti.f64, transposed: ti.i32,
              rows: ti.i32, segs: ti.i32, dt: ti.f64, box_w: ti.f64, box_h: ti.f64, spread: ndarr, large: ndarr,
              parts: ndarr, sync: ndarr, real: ti.template(), periodic: ti.template(), two_level: ti.template(),
              uniform: ti.template(), rounds: ti.template(), serial: ti.template()) -> ti.i32:
    """`begin_step` on a CPU's threads as one team (`circles.team`): the same stages, the same
    state bit for bit, with one start of the thread pool instead of one per loop. The first
    round runs in parts (`_first_round_in_parts`), the later `rounds` - 1 in chunks of their
    lists. `sync`: the team's counters (team.sync_slots()). With `serial` the team's loop runs on the
    calling thread, its members one after another (the first does every chunk, the others find
    them done): for tests of that claim of `circles.team`."""
    ti.static_assert(11 + 3 * rounds <= STAGES)
    n = pos.shape[0]
    ncells = cells_in(ncx, ncy, periodic)
    ti.loop_config(serialize=True)
    for _ in range(1):
        clear(sync)
        work[WALLED] = 0
        # As `_scan_contacts` begins.
        work[ROUND] += 1
        work[LIST0] = 0
        work[LIST1] = 0
        owned_starts(n, cell_of, parts, ncx, ncy, periodic)
    ti.loop_config(serialize=serial)
    for it in range(ti.static(loop_iterations())):
        me = member_of(it)
        if me >= 0:
            np_ = ti.static(count_parts())
            moved = ti.static((pos, vel, radius, n_contacts, walled, work, ti.cast(dt, real), box_w, box_h, real,
                               periodic, uniform))
            stage(sync, 0, np_, _team_move, (moved, cell_of, slot, cell_count, sorted_ids, parts, ncx, ncy, inv_cw,
                                             inv_ch, transposed, real, periodic), me)
            stage(sync, 1, 1, _team_strays, (cell_of, slot, cell_count, sorted_ids, parts), me)
            nchunks = chunks_of(ncells, ti.static(_scan_shape()[0]))
            stage(sync, 2, nchunks, _team_totals, (cell_count, cell_start, ncells), me)
            stage(sync, 3, 1, _team_ends, (cell_start, ncells), me)
            stage(sync, 4, nchunks, _team_starts, (cell_count, cell_start, ncells), me)
            stage(sync, 5, chunks_of(n, TEAM_SLOTS), _team_scatter, (cell_of, slot, cell_start, sorted_ids), me)
            stage(sync, 6, chunks_of(n, TEAM_SLOTS), _team_scan,
                  (pos, vel, radius, contacts, n_contacts, marked, work, cell_of, cell_start, sorted_ids, ncx, ncy,
                   rows, segs, box_w, box_h, spread, real, periodic, two_level, uniform), me)
            if ti.static(two_level):
                stage(sync, 7, chunks_of(work[NLARGE], TEAM_LIST), _team_scan_large,
                      (pos, vel, radius, contacts, n_contacts, marked, work, cell_of, cell_start, sorted_ids, ncx,
                       ncy, rows, segs, box_w, box_h, spread, large, real, periodic, two_level, uniform), me)
            first = ti.static((pos, vel, radius, inv_mass, ids, partner, picked, pair_count, virial, marked, contacts,
                     n_contacts, lists, work, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, box_w, box_h,
                     spread, real, periodic, two_level, uniform))
            stage(sync, 8, np_, _team_first_pick, first, me)
            stage(sync, 9, np_, _team_first_resolve, first, me)
            stage(sync, 10, 1, _team_next_round, (work, sync, 0, 0), me)
            for r in range(1, rounds):
                side = r % 2
                s = 11 + 3 * (r - 1)
                items = sync[value_slot(r)]
                chunks = chunks_of(items, TEAM_LIST)
                stage(sync, s, chunks, _team_pick,
                      (items, pos, vel, radius, inv_mass, ids, partner, picked, pair_count, virial, contacts,
                       n_contacts, lists, work, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, box_w, box_h,
                       spread, real, periodic, two_level, uniform, side, marked, False), me)
                stage(sync, s + 1, chunks, _team_resolve,
                      (items, pos, vel, radius, inv_mass, ids, partner, picked, pair_count, virial, marked, contacts,
                       n_contacts, lists, work, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, box_w, box_h,
                       spread, real, periodic, two_level, uniform, side, False), me)
                stage(sync, s + 2, 1, _team_next_round, (work, sync, side, r), me)
            if ti.static(not periodic):
                stage(sync, ti.static(11 + 3 * (rounds - 1)), chunks_of(work[WALLED], TEAM_LIST), _team_walls,
                      (walled, work, pos, vel, radius, inv_mass, wall_count, wall_impulse, box_w, box_h, real,
                       uniform), me)
    return work[LIST0]
