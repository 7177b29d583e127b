"""N environments stepped by K worker processes, each stepping its contiguous share of them in series: SB3's
``SubprocVecEnv`` runs one process per environment, which for N rendered environments on a few cores means N
processes, N EGL contexts and N pipe round trips per step; stable-baselines3 has no several-envs-per-process vector
env (DLR-RM/stable-baselines3#815). Here each worker holds a ``DummyVecEnv`` of its share and answers one message
per vector step, so the rendering of the N frames spreads over the K processes while the caller (the L-Net's
batched forward, the PPO update) runs in its own.

The workers hold ``numpy.array_split``'s shares of the N indices (contiguous, sizes differing by at most one; for
N = 5, K = 2: environments 0-2 and 3-4). Each environment is seeded, reset and stepped exactly as in a
``DummyVecEnv`` of the same ``env_fns``: the same observations, rewards, dones and infos, in the same order
(``tests/policy/test_grouped_env.py``).
"""

from __future__ import annotations

import multiprocessing as mp
from collections.abc import Callable, Sequence
from multiprocessing.connection import Connection
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv
from stable_baselines3.common.vec_env.base_vec_env import CloudpickleWrapper, VecEnvIndices, VecEnvObs, VecEnvStepReturn


def _worker(remote: Connection, parent_remote: Connection, env_fns: CloudpickleWrapper) -> None:
    """One worker's loop: a ``DummyVecEnv`` of its share, answering (command, data) messages; indices are local."""
    parent_remote.close()
    venv = DummyVecEnv(env_fns.var)
    try:
        while True:
            command, data = remote.recv()
            if command == "step":
                observations, rewards, dones, infos = venv.step(data)
                remote.send((observations, rewards, dones, infos, venv.reset_infos))
            elif command == "reset":
                venv._seeds, venv._options = data  # noqa: SLF001 - what VecEnv.seed/set_options set, per env
                remote.send((venv.reset(), venv.reset_infos))
            elif command == "get_spaces":
                remote.send((venv.observation_space, venv.action_space))
            elif command == "env_method":
                name, args, kwargs, indices = data
                remote.send(venv.env_method(name, *args, indices=indices, **kwargs))
            elif command == "has_attr":
                remote.send(venv.has_attr(data))
            elif command == "get_attr":
                remote.send(venv.get_attr(data[0], indices=data[1]))
            elif command == "set_attr":
                remote.send(venv.set_attr(data[0], data[1], indices=data[2]))
            elif command == "is_wrapped":
                remote.send(venv.env_is_wrapped(data[0], indices=data[1]))
            elif command == "close":
                venv.close()
                break
            else:
                raise NotImplementedError(f"{command!r} is not a command of the grouped env's worker")
    except (EOFError, KeyboardInterrupt):
        pass
    finally:
        remote.close()


class GroupedSubprocVecEnv(VecEnv):
    """``len(env_fns)`` environments in ``n_workers`` processes (at most one per environment), each stepping its
    share in series. Observations (arrays or dicts of arrays) have the environment index first, shape (N, ...)."""

    def __init__(self, env_fns: list[Callable[[], gym.Env]], n_workers: int, start_method: str | None = None
                 ) -> None:
        n_envs = len(env_fns)
        if not 1 <= n_workers <= n_envs:
            raise ValueError(f"n_workers: {n_workers} must be between 1 and the {n_envs} environments")
        self.shares = [share.tolist() for share in np.array_split(np.arange(n_envs), n_workers)]
        self.worker_of = np.concatenate([np.full(len(share), w) for w, share in enumerate(self.shares)])
        self.local_of = np.concatenate([np.arange(len(share)) for share in self.shares])
        if start_method is None:  # as SB3's SubprocVecEnv: fork is not thread safe
            start_method = "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"
        context = mp.get_context(start_method)
        self.remotes, work_remotes = zip(*[context.Pipe() for _ in range(n_workers)], strict=True)
        self.processes = []
        for work_remote, remote, share in zip(work_remotes, self.remotes, self.shares, strict=True):
            process = context.Process(target=_worker, daemon=True,  # a crashed parent leaves no worker behind
                                      args=(work_remote, remote, CloudpickleWrapper([env_fns[i] for i in share])))
            process.start()
            self.processes.append(process)
            work_remote.close()
        self.waiting, self.closed = False, False
        self.remotes[0].send(("get_spaces", None))
        observation_space, action_space = self.remotes[0].recv()
        super().__init__(n_envs, observation_space, action_space)

    def step_async(self, actions: np.ndarray) -> None:
        for remote, share in zip(self.remotes, self.shares, strict=True):
            remote.send(("step", np.asarray(actions)[share]))
        self.waiting = True

    def step_wait(self) -> VecEnvStepReturn:
        results = [remote.recv() for remote in self.remotes]
        self.waiting = False
        observations, rewards, dones, infos, reset_infos = zip(*results, strict=True)
        self.reset_infos = [info for share in reset_infos for info in share]
        return (self._concatenate(observations), np.concatenate(rewards), np.concatenate(dones),
                [info for share in infos for info in share])

    def reset(self) -> VecEnvObs:
        for remote, share in zip(self.remotes, self.shares, strict=True):
            remote.send(("reset", ([self._seeds[i] for i in share], [self._options[i] for i in share])))
        observations, reset_infos = zip(*[remote.recv() for remote in self.remotes], strict=True)
        self.reset_infos = [info for share in reset_infos for info in share]
        self._reset_seeds()  # seeds and options are used once, as in SB3's vector envs
        self._reset_options()
        return self._concatenate(observations)

    def close(self) -> None:
        if self.closed:
            return
        if self.waiting:
            for remote in self.remotes:
                remote.recv()
        for remote in self.remotes:
            remote.send(("close", None))
        for process in self.processes:
            process.join()
        for remote in self.remotes:
            remote.close()
        self.closed = True

    def has_attr(self, attr_name: str) -> bool:
        """Whether every env has ``attr_name``, asked where they live (VecEnv's default fetches the attribute, and a
        bound method cannot cross the pipe)."""
        for remote in self.remotes:
            remote.send(("has_attr", attr_name))
        return all([remote.recv() for remote in self.remotes])

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return self._ask("get_attr", lambda local: (attr_name, local), indices)

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        self._ask("set_attr", lambda local: (attr_name, value, local), indices)

    def env_method(self, method_name: str, *method_args: Any, indices: VecEnvIndices = None,
                   **method_kwargs: Any) -> list[Any]:
        return self._ask("env_method", lambda local: (method_name, method_args, method_kwargs, local), indices)

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return self._ask("is_wrapped", lambda local: (wrapper_class, local), indices)

    def _ask(self, command: str, message: Callable[[list[int]], tuple], indices: VecEnvIndices) -> list[Any]:
        """Send ``command`` to each worker holding one of ``indices`` (its local indices in the message), and the
        answers in the order of ``indices`` (``None`` answers for commands that return nothing)."""
        wanted = list(self._get_indices(indices))
        workers = sorted({int(self.worker_of[i]) for i in wanted})
        for worker in workers:
            local = [int(self.local_of[i]) for i in wanted if self.worker_of[i] == worker]
            self.remotes[worker].send((command, message(local)))
        answers = {worker: self.remotes[worker].recv() for worker in workers}
        if any(answer is None for answer in answers.values()):
            return [None] * len(wanted)
        found = {worker: iter(answer) for worker, answer in answers.items()}
        return [next(found[int(self.worker_of[i])]) for i in wanted]

    def _concatenate(self, shares: Sequence[VecEnvObs]) -> VecEnvObs:
        """The workers' observations, (n_i, ...) each, as one (N, ...) array (or dict of them)."""
        if isinstance(shares[0], dict):
            return {key: np.concatenate([share[key] for share in shares]) for key in shares[0]}
        return np.concatenate(shares)
