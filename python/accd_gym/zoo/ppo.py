"""rl-zoo3 hyperparameters of PPO for every registered id (``--conf-file accd_gym.zoo.ppo``)."""

from accd_gym.zoo import zoo_hyperparams

#: What rl-zoo3 reads: env id -> hyperparameters.
hyperparams = zoo_hyperparams("ppo")
