"""The environments: the single env (:mod:`~accd_gym.envs.env`), the native vector env
(:mod:`~accd_gym.envs.vector`) and the stable-baselines3 VecEnv (:mod:`~accd_gym.envs.sb3`) over
the Rust batch core (:mod:`~accd_gym.envs.core_env`); the task they share (spaces, observation
table, info fields, seeds: :mod:`~accd_gym.envs.task`); configurations
(:mod:`~accd_gym.envs.config`), named overrides (:mod:`~accd_gym.envs.overrides`) and the
benchmark tiers' registered ids (:mod:`~accd_gym.envs.tiers`); off-screen frames
(:mod:`~accd_gym.envs.render`)."""
