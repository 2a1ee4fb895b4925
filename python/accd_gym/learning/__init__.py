"""Reinforcement-learning training: stable-baselines3 (:mod:`~accd_gym.learning.training`) and
RLlib (:mod:`~accd_gym.learning.rllib`, ``pip install 'accd-gym[ray]'``)."""
