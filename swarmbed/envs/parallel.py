"""A PettingZoo ``ParallelEnv`` whose agents are swarmbed's agents, over the emulated radio.

``engine="processes"`` (default): ``reset(seed)`` starts a lock-step run of the experiment with the
``external`` allocator (its processes, the hub, the netem proxy, as ``swarmbed run`` does) in a
thread of this process; ``step(actions)`` hands every agent's decision for the tick in hand to the
coordinator, which puts it in that agent's tick sample; the agent's allocator answers with it, its
tree runs it, the world and the radio move on one tick, and the next tick's observations come back.
``engine="inprocess"``: the learner owns the loop; every agent's runtime and the radio step in this
process (:class:`~swarmbed.launch.inprocess.InProcessRun`), one tick a ``step``, with no
thread and no queue. Either way the bytes, the ledger and the result files are those of a normal
run, and the same seed and actions give the same observations and files on both engines
(``docs/learning.md``).

Spaces, per agent (``max_tasks`` = K, N agents):

* observation, a ``Dict``: ``self`` (x, y, heading, speed), ``tasks`` (K rows of dx, dy and
  remaining work of the tasks in view, nearest first, ties to the lower id; zeros past the last),
  ``task_mask`` (which rows hold a task), ``action_mask`` (the actions that choose something),
  ``heard_from`` (the agents whose radio messages it
  received this tick: range, loss, bursts and caps shape it);
* action, ``Discrete(K + 1)``: 0 chooses no task (the agent's tree explores), j the j-th row of
  ``tasks``; a row the mask marks empty also chooses none. With ``broadcast=True``, K more actions:
  K + j chooses row j *and* broadcasts a claim of its task over the radio (a ``claim`` message,
  counted, ranged and lost like any other), and the observation gains ``claimed`` (K counts: the
  claims heard this tick for each row's task). With a ``fallback`` allocator, one more action, the
  last, lets it decide. Where tasks may need a team (MT-SR's ``robots_needed``), the observation
  gains ``teams``: K rows of (robots the row's task needs, robots on it at the last tick).

Rewards: the team's progress over the tick, the increase of the scenario's ``reward_key``
(``tasks_completed`` in MT-SR, ``rescued`` in search and rescue), to every live agent.
Terminations: an agent lost to a failure, or every agent when the world is done; truncations:
every agent when the run reaches its duration.
"""

from __future__ import annotations

import json
import math
import queue
import re
import shutil
import tempfile
import threading
import weakref
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

try:
    from gymnasium import spaces
    from pettingzoo import ParallelEnv
except ImportError as exc:  # an optional extra
    raise ImportError("swarmbed.envs needs the envs extra: pip install 'swarmbed[envs]'") from exc

import swarmbed.experiments
from swarmbed import config as cfg
from swarmbed.extension.view import coalitions_of
from swarmbed.launch.access import claim_folder, remove_orphaned_folders
from swarmbed.launch.inprocess import ENGINES, InProcessRun
from swarmbed.launch.runner import RunResult, run_experiment
from swarmbed.plugins.external import ANNOUNCE, CLAIM, DEFER
from swarmbed.wire.codec import delivered_in, unpack
from swarmbed.wire.errors import WireError

QUICKSTART = Path(swarmbed.experiments.__file__).resolve().parent / "quickstart.yaml"
STEP_TIMEOUT = 600.0  # wall seconds a step waits for the run's next tick before calling the run stuck


class EnvError(RuntimeError):
    """The run under the environment failed (its processes, its configuration)."""


def agent_view(
    obs: Any, inbox: bytes | None, max_tasks: int, n: int, claims: bool = False, teams: bool = False
) -> tuple[dict[str, np.ndarray], list[int]]:
    """One agent's observation (the spaces of the module docstring) and the task ids of its rows;
    ``claims``: with ``claimed``, the claims its inbox holds for each row's task; ``teams``: with
    ``teams``, each row's task's (robots needed, robots on it)."""
    tasks = obs.tasks
    x, y = obs.x, obs.y
    rows = np.zeros((max_tasks, 3), dtype=np.float32)
    mask = np.zeros(max_tasks, dtype=np.int8)
    chosen: list[int] = []
    if len(tasks):
        ids, txs, tys, left = tasks["id"].tolist(), tasks["x"].tolist(), tasks["y"].tolist(), tasks["remaining"]
        # nearest first, ties to the lower id, with the distance the plugins use (math.hypot, which
        # may differ from numpy's in the last bit): action 1 is then the nearest allocator's choice
        order = sorted(range(len(ids)), key=lambda j: (math.hypot(txs[j] - x, tys[j] - y), ids[j]))[:max_tasks]
        m = len(order)
        rows[:m, 0] = tasks["x"][order] - x
        rows[:m, 1] = tasks["y"][order] - y
        rows[:m, 2] = left[order]
        mask[:m] = 1
        chosen = [ids[j] for j in order]
    heard = np.zeros(n, dtype=np.int8)
    copies = delivered_in(inbox)
    heard[[c.sender for c in copies if 0 <= c.sender < n]] = 1
    me = np.array((x, y, obs.heading, obs.speed), dtype=np.float32)
    view: dict[str, np.ndarray] = {"self": me, "tasks": rows, "task_mask": mask, "heard_from": heard}
    if claims:
        row_of: dict[int | None, int] = {task: j for j, task in enumerate(chosen)}
        claimed = np.zeros(max_tasks, dtype=np.float32)
        for c in copies:
            if c.kind == CLAIM and (j := row_of.get(_claimed_task(c.payload))) is not None:
                claimed[j] += 1
        view["claimed"] = claimed
    if teams:
        team = np.zeros((max_tasks, 2), dtype=np.float32)
        team[: len(chosen), 0] = 1.0
        for task, (needed, on) in coalitions_of(obs).items():
            if task in chosen:
                team[chosen.index(task)] = (needed, on)
        view["teams"] = team
    return view, chosen


def _claimed_task(payload: bytes) -> int | None:
    """The task id a claim message holds; None for anything else (a crafted payload)."""
    try:
        task = unpack(payload)
    except WireError:
        return None
    return task if isinstance(task, int) and not isinstance(task, bool) else None


def with_action_mask(view: dict[str, np.ndarray], deferring: bool, announcing: bool = False) -> dict[str, np.ndarray]:
    """``view`` with ``action_mask``: the actions that choose something (0, no task, always; j where
    row j holds a task, and K + j with ``announcing``; the fallback's action where there is one), as
    sb3-contrib's MaskablePPO and TorchRL's PettingZoo wrapper read it."""
    k = len(view["task_mask"])
    legal = np.ones(1 + k * (2 if announcing else 1) + (1 if deferring else 0), dtype=np.int8)
    legal[1 : 1 + k] = view["task_mask"]
    if announcing:
        legal[1 + k : 1 + 2 * k] = view["task_mask"]
    view["action_mask"] = legal
    return view


def _counters(world: Any) -> list[str]:
    """The world's numeric counters (what a reward may be the increase of)."""
    return sorted(k for k, v in world.row().items() if isinstance(v, (int, float)) and k != "tick")


class _Bridge:
    """The coordinator's side: it hands each tick's observations to the environment and waits for
    the decisions (the coordinator calls :meth:`decide` from the run's thread before each tick)."""

    def __init__(self, max_tasks: int, n: int, reward_key: str, claims: bool = False, teams: bool = False) -> None:
        self.max_tasks, self.n, self.reward_key, self.claims, self.teams = max_tasks, n, reward_key, claims, teams
        self.counters: list[str] = []  # the world's numeric counters, as of the first tick
        self.to_env: queue.Queue = queue.Queue()
        self.to_run: queue.Queue = queue.Queue()
        self.coordinator: Any = None
        self.stopping = False

    # a run observer: the coordinator, once every process joined; the end of the ticks
    def start(self, run: Any) -> None:
        self.coordinator = run.coordinator

    def stop(self) -> None:
        world = self.coordinator.world if self.coordinator is not None else None
        if world is not None:
            self.to_env.put(("end", self._progress(world), bool(world.finished)))

    def _progress(self, world: Any) -> float:
        return float(world.row().get(self.reward_key, 0.0))

    def decide(
        self, tick: int, world: Any, observed: Mapping[int, Any], inboxes: Mapping[int, bytes]
    ) -> dict[int, int]:
        if self.stopping:
            return {}
        if not self.counters:
            self.counters = _counters(world)
        views = {i: self._view(obs, inboxes.get(i)) for i, obs in observed.items()}
        self.to_env.put(("tick", tick, views, self._progress(world)))
        decisions = self.to_run.get()
        if decisions is None:  # the environment is done with this run: end it after this tick
            self.stopping = True
            self.coordinator.stop.ask()
            return {}
        return decisions

    def _view(self, obs: Any, inbox: bytes | None) -> tuple[dict[str, np.ndarray], list[int]]:
        return agent_view(obs, inbox, self.max_tasks, self.n, self.claims, self.teams)


class SwarmbedParallelEnv(ParallelEnv):
    """Any swarmbed experiment as a PettingZoo parallel environment (see the module docstring).

    ``config``: an experiment file (default: the quick start); ``sets``: ``KEY=VALUE`` overrides as
    ``swarmbed run --set`` takes them (loss, bursts, range: what the agents hear); ``out_dir``: where
    each reset's run folder goes (``run_0``, ``run_1``, ...; default: a temporary folder removed by
    :meth:`close`). ``fallback``: a registered allocator (``fcg``, ``cbba``, ``grape``) that runs in
    every agent beside the learner's decisions, observing and talking over the radio as in a run of
    its own; the action :attr:`defer` (K + 1) lets it decide, so it plays as a policy on the same
    seeds (its parameters: the experiment's ``allocator:`` keys when it names the same allocator).
    ``broadcast``: K more actions, each choosing a row and broadcasting a claim of its task, and
    ``claimed`` in the observation (the module docstring)."""

    metadata = {"name": "swarmbed_v0", "render_modes": [], "is_parallelizable": True}
    render_mode = None  # nothing to render (SuperSuit's vector wrappers read it)

    def __init__(
        self,
        config: str | Path = QUICKSTART,
        sets: Sequence[str] = (),
        max_tasks: int = 8,
        reward_key: str | None = None,
        out_dir: str | Path | None = None,
        fallback: str | None = None,
        engine: str = "processes",
        broadcast: bool = False,
    ) -> None:
        if engine not in ENGINES:
            raise ValueError(f"engine {engine!r}: one of {', '.join(ENGINES)}")
        if not isinstance(broadcast, (bool, np.bool_)):  # "false" is a non-empty string: bool() reads True
            raise ValueError(f"broadcast {broadcast!r}: True or False")
        self.engine = engine
        if isinstance(max_tasks, (bool, np.bool_)) or not isinstance(max_tasks, (int, np.integer)) or max_tasks < 1:
            raise ValueError(f"max_tasks {max_tasks!r}: the rows of tasks an agent sees, a whole number of at least 1")
        self.config = Path(config)
        given = cfg.load(self.config, list(sets))
        external: dict[str, Any] = {"name": "external"}
        if fallback is not None:
            own = given.allocator.model_dump(exclude={"name"}) if given.allocator.name == fallback else {}
            external.update(fallback=fallback, fallback_scenario=given.scenario.kind, fallback_params=own)
        self.sets = [*sets, f"allocator={json.dumps(external)}"]
        self.exp = cfg.load(self.config, self.sets)
        if self.exp.run.clock != "lockstep":
            raise ValueError("swarmbed.envs steps the lock-step clock: run.clock must be lockstep")
        n = self.exp.agents.count
        self.max_tasks = max_tasks
        self.reward_key = reward_key or ("rescued" if self.exp.scenario.kind == "sar" else "tasks_completed")
        self.possible_agents = [f"agent_{i}" for i in range(n)]
        self._index = {name: i for i, name in enumerate(self.possible_agents)}
        inf = np.float32(np.inf)
        self.broadcast = bool(broadcast)
        actions = 1 + max_tasks * (2 if self.broadcast else 1) + (1 if fallback is not None else 0)
        space = {
            "self": spaces.Box(-inf, inf, (4,), np.float32),
            "tasks": spaces.Box(-inf, inf, (max_tasks, 3), np.float32),
            "task_mask": spaces.MultiBinary(max_tasks),
            "heard_from": spaces.MultiBinary(n),
            "action_mask": spaces.MultiBinary(actions),
        }
        if self.broadcast:
            space["claimed"] = spaces.Box(np.float32(0), np.float32(n), (max_tasks,), np.float32)
        self.teams = bool(getattr(cfg.resolve_experiment(self.exp).scenario().params, "teamwork", False))
        if self.teams:
            space["teams"] = spaces.Box(np.float32(0), np.float32(n), (max_tasks, 2), np.float32)
        self._observation_space = spaces.Dict(space)
        #: the action that lets the fallback allocator decide (only with ``fallback``): the last
        self.defer: int | None = actions - 1 if fallback is not None else None
        self._action_space = spaces.Discrete(actions)
        self._own_dir = out_dir is None
        if out_dir is None:  # removed by close(), at exit, or by the next swarmbed process if this one was killed
            remove_orphaned_folders()
            self.out_dir = Path(tempfile.mkdtemp(prefix="swarmbed-env-"))
            claim_folder(self.out_dir)
            self._cleanup = weakref.finalize(self, shutil.rmtree, self.out_dir, ignore_errors=True)
        else:
            self.out_dir = Path(out_dir)
        self.runs = 0  # the runs this environment started
        self._seeds: np.random.Generator | None = None  # draws the seed of a reset() given none
        self.agents: list[str] = []
        self.results: list[RunResult] = []  # every finished run of this environment, in order
        self._bridge: _Bridge | None = None
        self._inprocess: InProcessRun | None = None  # engine="inprocess": the run this process steps
        self._thread: threading.Thread | None = None
        self._failure: BaseException | None = None
        self._choices: dict[str, list[int]] = {}
        self._last_obs: dict[str, dict[str, np.ndarray]] = {}
        self._progress = 0.0

    def observation_space(self, agent: str) -> spaces.Space:
        return self._observation_space

    def action_space(self, agent: str) -> spaces.Space:
        return self._action_space

    # -- the run under the environment -------------------------------------------------------------
    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        self._end_run()
        if seed is None and self._seeds is not None:  # a new world each episode, drawn from the last seed
            seed = int(self._seeds.integers(2**31))
        else:  # a seed given, or the first episode's: the configuration's own
            seed = self.exp.run.seed if seed is None else seed
            self._seeds = np.random.default_rng(seed)
        if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed {seed!r}: a whole number of at least 0")
        # the configuration checked once, in the constructor; each episode changes only its seed
        exp = self.exp.model_copy(update={"run": self.exp.run.model_copy(update={"seed": int(seed)})})
        out = self._next_run_dir()
        self.runs += 1
        if self.engine == "inprocess":
            self._inprocess = InProcessRun(exp, out, env=True)
            counters = _counters(self._inprocess.world)
            return self._first(self._inprocess_item(), counters)
        self._bridge = bridge = _Bridge(self.max_tasks, exp.agents.count, self.reward_key, self.broadcast, self.teams)
        self._failure = None

        def run() -> None:
            try:
                self.results.append(run_experiment(exp, out, progress=False, observers=[bridge], decider=bridge))
            except BaseException as exc:  # handed to the caller of reset or step
                self._failure = exc
            finally:
                bridge.to_env.put(("done",))

        self._thread = threading.Thread(target=run, name=f"swarmbed-env-run-{self.runs}", daemon=True)
        self._thread.start()
        item = self._next()
        return self._first(item, bridge.counters)

    def _first(self, item: tuple, counters: list[str]) -> tuple[dict, dict]:
        """reset()'s answer from the run's first tick."""
        if item[0] != "tick":
            raise EnvError("the run ended before its first tick")
        if self.reward_key not in counters:
            self._end_run()
            raise ValueError(
                f"reward_key {self.reward_key!r}: not a counter of this world (one of {', '.join(counters)})"
            )
        _, _tick, views, progress = item
        self._progress = progress
        self.agents = [self.possible_agents[i] for i in sorted(views)]
        obs = self._observe(views)
        return obs, {a: {"task_ids": self._choices[a]} for a in self.agents}

    def _next_run_dir(self) -> Path:
        """``out_dir/run_<k>``, k after every ``run_<j>`` the folder holds: a run never replaces the
        results of an earlier one, this environment's or another's."""
        taken = [int(m.group(1)) for p in self.out_dir.glob("run_*") if (m := re.fullmatch(r"run_(\d+)", p.name))]
        return self.out_dir / f"run_{max(taken, default=-1) + 1}"

    def step(self, actions: Mapping[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        if not isinstance(actions, Mapping):
            raise ValueError(f"actions: a mapping of agent name to action, not {type(actions).__name__}")
        if (self._bridge is None and self._inprocess is None) or not self.agents:
            raise EnvError("step() before reset(), or after every agent is done")
        decisions = self._decisions(actions)
        if self._inprocess is not None:
            self._inprocess.advance(decisions)
            item = self._inprocess_item()
        else:
            assert self._bridge is not None
            self._bridge.to_run.put(decisions)
            item = self._next()
        acting = list(self.agents)
        if item[0] == "tick":
            _, _tick, views, progress = item
            reward = progress - self._progress
            self._progress = progress
            alive = {self.possible_agents[i] for i in views}
            obs = self._observe(views)
            terminations = {a: a not in alive for a in acting}
            truncations = dict.fromkeys(acting, False)
            self.agents = [a for a in acting if a in alive]
            if not self.agents:  # every agent lost: the run has no one left to step for
                self._end_run()
        else:  # the run is over: its duration (truncation) or a finished world (termination)
            progress, finished = (item[1], item[2]) if item[0] == "end" else (self._progress, False)
            reward = progress - self._progress
            self._progress = progress
            obs = {a: self._last_obs[a] for a in acting}
            terminations = dict.fromkeys(acting, finished)
            truncations = dict.fromkeys(acting, not finished)
            self.agents = []
            self._end_run()
            if self._failure is not None:  # the ticks were over, writing the results failed
                failure, self._failure = self._failure, None
                raise EnvError(f"the run failed: {failure}") from failure
        rewards = dict.fromkeys(acting, float(reward))
        infos = {a: {"task_ids": self._choices.get(a, [])} for a in acting}
        return {a: obs[a] for a in acting if a in obs}, rewards, terminations, truncations, infos

    def _decisions(self, actions: Mapping[str, Any]) -> dict[int, int]:
        """Each agent's task id (-1: none) from its action; one line naming the agent and the value
        for anything outside the action space, before the tick is sent."""
        decisions = {}
        live = set(self.agents)
        for agent, action in actions.items():
            if agent not in self._index or agent not in live:
                raise ValueError(f"{agent!r}: not an agent of this step ({', '.join(self.agents[:5])} ...)")
            top = self._action_space.n - 1
            if isinstance(action, (bool, np.bool_)) or not isinstance(action, (int, np.integer)):
                raise ValueError(f"{agent}: action {action!r} is not an integer in 0..{top}")
            choice = int(action)
            if not 0 <= choice <= top:
                raise ValueError(f"{agent}: action {choice} is not in 0..{top}")
            ids, k = self._choices[agent], self.max_tasks
            announce = self.broadcast and k < choice <= 2 * k
            row = choice - k if announce else choice
            if choice == self.defer:
                decisions[self._index[agent]] = DEFER
            elif 0 < row <= len(ids):
                decisions[self._index[agent]] = ids[row - 1] + (ANNOUNCE if announce else 0)
            else:
                decisions[self._index[agent]] = -1
        return decisions

    def _observe(self, views: Mapping[int, tuple[dict, list[int]]]) -> dict[str, dict[str, np.ndarray]]:
        obs = {}
        for i, (view, ids) in views.items():
            name = self.possible_agents[i]
            obs[name], self._choices[name] = with_action_mask(view, self.defer is not None, self.broadcast), ids
        self._last_obs.update(obs)
        return obs

    def _inprocess_item(self) -> tuple:
        """What the bridge would hand over, from the run this process steps: the tick in hand's
        views and the progress so far, or the end of the run (its result files written)."""
        run = self._inprocess
        assert run is not None
        progress = float(run.world.row().get(self.reward_key, 0.0))
        if run.over:
            self.results.append(run.finish())
            return ("end", progress, bool(run.world.finished))
        hand, n = run.observe(), self.exp.agents.count
        views = {
            i: agent_view(obs, run.inboxes.get(i), self.max_tasks, n, self.broadcast, self.teams)
            for i, obs in hand.observed.items()
        }
        return ("tick", hand.k, views, progress)

    def _next(self) -> tuple:
        assert self._bridge is not None
        try:
            item = self._bridge.to_env.get(timeout=STEP_TIMEOUT)
        except queue.Empty:
            raise EnvError(f"no tick from the run within {STEP_TIMEOUT:.0f} s") from None
        if item[0] == "done" and self._failure is not None:
            failure, self._failure = self._failure, None
            raise EnvError(f"the run failed: {failure}") from failure
        return item

    def _end_run(self) -> None:
        """Stop the run under way, if any, and wait for its processes to leave (in-process: write the
        result files of the ticks stepped)."""
        run, self._inprocess = self._inprocess, None
        if run is not None and run.result is None:
            self.results.append(run.finish())
        bridge, thread = self._bridge, self._thread
        if thread is not None and thread.is_alive() and bridge is not None:
            bridge.to_run.put(None)  # the coordinator may wait for decisions: let it stop
        if thread is not None:
            thread.join(timeout=120)
        self._thread = None

    def close(self) -> None:
        self._end_run()
        self.agents = []
        if self._own_dir:
            self._cleanup()


def parallel_env(**kwargs: Any) -> SwarmbedParallelEnv:
    """PettingZoo's usual constructor name."""
    return SwarmbedParallelEnv(**kwargs)
