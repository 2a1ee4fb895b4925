"""rl-zoo3 hyperparameters of residual SAC for every registered id (``--algo sac --conf-file accd_gym.zoo.residual_sac``)."""

from accd_gym.zoo import zoo_hyperparams

#: What rl-zoo3 reads: env id -> hyperparameters.
hyperparams = zoo_hyperparams("residual_sac")
