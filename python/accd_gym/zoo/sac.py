"""rl-zoo3 hyperparameters of SAC for every registered id (``--conf-file accd_gym.zoo.sac``)."""

from accd_gym.zoo import zoo_hyperparams

#: What rl-zoo3 reads: env id -> hyperparameters.
hyperparams = zoo_hyperparams("sac")
