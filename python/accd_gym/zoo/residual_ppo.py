"""rl-zoo3 hyperparameters of residual PPO for every registered id (``--algo ppo --conf-file accd_gym.zoo.residual_ppo``)."""

from accd_gym.zoo import zoo_hyperparams

#: What rl-zoo3 reads: env id -> hyperparameters.
hyperparams = zoo_hyperparams("residual_ppo")
