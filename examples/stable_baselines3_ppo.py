"""Train Stable-Baselines3's PPO on a crllk task through the Gymnasium adapter.

    python examples/stable_baselines3_ppo.py --env crllk/SmallLoop-State-v0 --steps 20000

Stable-Baselines3 (2.9.2, in the ``dev`` extra) installs beside crllk's pinned torch. Its PPO
knows nothing of constraints: it maximises the reward (forward progress) alone, while the
per-step costs stay in ``info`` (``info["cost"]``), where a constrained learner would read them.
The script then drives a few episodes with the trained policy and prints their mean return
(m travelled) and summed cost per constraint.
"""

from __future__ import annotations

import argparse

import gymnasium
import numpy as np
from stable_baselines3 import PPO

import crllk.gym  # noqa: F401  (registers the crllk/... ids)


def train(env_id: str, steps: int, seed: int = 0) -> PPO:
    """PPO trained for ``steps`` environment steps."""
    env = gymnasium.make(env_id)
    policy = "CnnPolicy" if len(env.observation_space.shape) == 3 else "MlpPolicy"
    model = PPO(policy, env, n_steps=min(256, steps), batch_size=64, seed=seed, verbose=0)
    return model.learn(total_timesteps=steps)


def drive(model: PPO, env_id: str, episodes: int, seed: int = 1_000_000) -> dict[str, float]:
    """Mean return and mean summed cost per constraint over ``episodes`` episodes."""
    env = gymnasium.make(env_id)
    totals: dict[str, list[float]] = {}
    for episode in range(episodes):
        observation, _ = env.reset(seed=seed + episode)
        sums: dict[str, float] = {"return": 0.0}
        done = False
        while not done:
            action, _ = model.predict(observation, deterministic=True)
            observation, reward, terminated, truncated, info = env.step(action)
            sums["return"] += reward
            for key, value in info.items():
                if key.startswith("cost"):
                    sums[key] = sums.get(key, 0.0) + value
            done = terminated or truncated
        for key, value in sums.items():
            totals.setdefault(key, []).append(value)
    env.close()
    return {key: float(np.mean(values)) for key, values in totals.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="crllk/SmallLoop-State-v0")
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--episodes", type=int, default=5)
    args = parser.parse_args()
    print(drive(train(args.env, args.steps), args.env, args.episodes))


if __name__ == "__main__":
    main()
