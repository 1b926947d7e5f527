"""RLlib glue: both env tiers registered for Ray RLlib, and a deterministic action from a trained module.

    from trn_env.env.rllib import register_rllib_envs
    names = register_rllib_envs()            # {"full": "trn_env/TerrainNav-v0", "fast": ... if registered}
    config = PPOConfig().environment(names["full"], env_config={"scenario": "basin_route", ...})

RLlib (the `rllib` extra: `pip install 'trn-env[rllib]'`) builds envs from a creator registered under a name
(`ray.tune.registry.register_env`); the names are the gymnasium ids. The full-fidelity tier
(`trn_env/TerrainNav-v0`, one JSBSim aircraft per env) is vectorised by RLlib (`gym_env_vectorize_mode`
"sync", or "async" for a process per sub-env); the fast tier (`trn_env/TerrainNavFast-v0`, a native
`gymnasium.vector.VectorEnv` of N aircraft) is registered whenever its id is in gymnasium's registry (after
`import trn_env`, once the tier exists) and must be run with `gym_env_vectorize_mode="vector_entry_point"`
(`rllib_env_settings` gives the right settings for either). Observations are rescaled to [-1, 1] by the
observation space's bounds (the same map as `trn_env.env.sb3_features.BoundsScaledExtractor`), so RLlib's
default network sees inputs of one scale; `env_config["scale_observations"] = False` keeps them raw.

`env_config` holds the env's keyword arguments (JSON types), plus `scale_observations`; RLlib's own keys
(`worker_index`, `num_workers`, `num_envs`, ...) are taken off before the env is built.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

RLLIB_INSTALL = "pip install 'trn-env[rllib]'"
FULL_ID = "trn_env/TerrainNav-v0"
FAST_ID = "trn_env/TerrainNavFast-v0"
_RLLIB_KEYS = ("num_envs", "worker_index", "num_workers", "remote", "vector_index")


class RLlibNotInstalled(ImportError):
    """Ray RLlib is missing: the message carries the install command."""


def require_rllib() -> None:
    """Import check: RLlibNotInstalled (one line, the install command) when ray[rllib] is missing."""
    try:
        import ray.rllib  # noqa: F401
        import ray.tune.registry  # noqa: F401
        import tree  # noqa: F401   # dm_tree: an rllib-extra dependency that bare ray lacks
    except ImportError as err:
        raise RLlibNotInstalled(f"RLlib is not installed ({err.name or err}): {RLLIB_INSTALL}") from None


def _env_kwargs(env_config) -> tuple[dict[str, Any], bool, int]:
    cfg = dict(env_config or {})
    num_envs = int(cfg.pop("num_envs", 1))
    for k in _RLLIB_KEYS:
        cfg.pop(k, None)
    scale = cfg.pop("scale_observations", True)
    if not isinstance(scale, bool):
        raise ValueError(f"env_config['scale_observations'] must be a bool, got {scale!r}")
    return cfg, scale, num_envs


def make_full_env(env_config=None) -> gym.Env:
    """TerrainNav-v0 from an RLlib env_config (its keyword arguments), observations rescaled to [-1, 1]."""
    kwargs, scale, _ = _env_kwargs(env_config)
    env = gym.make(FULL_ID, **kwargs)
    if scale:
        env = gym.wrappers.RescaleObservation(env, np.float32(-1.0), np.float32(1.0))
    return env


def make_fast_env(env_config=None) -> gym.vector.VectorEnv:
    """TerrainNavFast-v0 (a native VectorEnv of env_config['num_envs'] aircraft) from an RLlib env_config,
    observations rescaled to [-1, 1]; the full tier's own settings (route_task.FULL_TIER_ONLY, e.g. JSBSim's
    step) are dropped, so one env_config serves both tiers. ValueError if the fast tier is not registered."""
    if FAST_ID not in gym.registry:
        raise ValueError(f"{FAST_ID} is not registered (import trn_env; the fast tier may not be installed)")
    from trn_env.env.route_task import fast_tier_kwargs

    kwargs, scale, num_envs = _env_kwargs(env_config)
    venv = gym.make_vec(FAST_ID, num_envs=num_envs, vectorization_mode="vector_entry_point",
                        **fast_tier_kwargs(kwargs))
    if scale:
        from gymnasium.wrappers.vector import RescaleObservation
        venv = RescaleObservation(venv, np.float32(-1.0), np.float32(1.0))
    return venv


def register_rllib_envs() -> dict[str, str]:
    """Register the env tiers with RLlib under their gymnasium ids; returns {"full": id[, "fast": id]} (the
    fast tier only when gymnasium knows its id). RLlibNotInstalled without the extra."""
    require_rllib()
    from ray.tune.registry import register_env  # (the gymnasium ids: registered by `import trn_env`)

    out = {"full": FULL_ID}
    register_env(FULL_ID, make_full_env)
    if FAST_ID in gym.registry:
        register_env(FAST_ID, make_fast_env)
        out["fast"] = FAST_ID
    return out


def rllib_env_settings(tier: str) -> dict[str, Any]:
    """`AlgorithmConfig.env_runners(...)` settings that an env tier needs ("full" or "fast")."""
    if tier == "full":
        return {"gym_env_vectorize_mode": "sync"}
    if tier == "fast":
        return {"gym_env_vectorize_mode": "vector_entry_point"}
    raise ValueError(f"tier must be 'full' or 'fast', got {tier!r}")


def deterministic_action(module, obs: np.ndarray) -> np.ndarray:
    """The mean action of an RLlib RLModule with a diagonal-Gaussian head (PPO's default for a Box action
    space) for one observation (already scaled as the env gives it), clipped to [-1, 1]."""
    import torch
    from ray.rllib.core.columns import Columns

    with torch.no_grad():
        out = module.forward_inference({Columns.OBS: torch.as_tensor(np.asarray(obs, np.float32)[None])})
    inputs = out[Columns.ACTION_DIST_INPUTS][0].numpy()
    n = inputs.shape[0] // 2                     # (means, log stds)
    return np.clip(inputs[:n], -1.0, 1.0).astype(np.float32)
