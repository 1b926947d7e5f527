"""The gymnasium env runs with the RBPF as its navigator (a short episode, reproducible by the reset seed)."""

import numpy as np


def test_env_with_rbpf_steps_and_reproduces():
    import gymnasium

    import trn_env  # noqa: F401 - registers the env ids

    def episode(seed):
        env = gymnasium.make("trn_env/TerrainNav-v0", navigator="rbpf", max_episode_s=10.0,
                             decision_interval_s=5.0)
        obs, info = env.reset(seed=seed)
        out = [obs]
        for _ in range(2):
            obs, reward, term, trunc, info = env.step(env.action_space.sample() * 0 + 0)
            out.append(obs)
            if term or trunc:
                break
        env.close()
        return np.array(out)

    a = episode(3)
    b = episode(3)
    assert np.all(np.isfinite(a)) and a.shape[0] >= 2
    assert np.array_equal(a, b)
