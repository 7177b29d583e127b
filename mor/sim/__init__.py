"""The MOR world: arena, rules, tasks as Gymnasium environments, oracle and views.

Importing this package registers ``MOR/Pick-v0``, ``MOR/Drop-v0`` and ``MOR/Rearrange-v0``. Each env enforces
its own horizon (150, 150, 1000 steps; the ``horizon`` keyword changes it) so that the episode's metrics are
in ``info`` on the truncating step too; no TimeLimit wrapper is added.
"""

from gymnasium.envs.registration import register, registry

#: task name -> (Gymnasium id, env class in mor.sim.tasks)
TASKS: dict[str, tuple[str, str]] = {
    "pick": ("MOR/Pick-v0", "PickEnv"),
    "drop": ("MOR/Drop-v0", "DropEnv"),
    "rearrange": ("MOR/Rearrange-v0", "RearrangeEnv"),
}

for _env_id, _class_name in TASKS.values():
    if _env_id not in registry:
        register(id=_env_id, entry_point=f"mor.sim.tasks:{_class_name}")
