"""Evaluating policies: resolving any policy spec (:mod:`~accd_gym.evals.policies`; the shipped
policies' catalog: :mod:`~accd_gym.evals.shipped`), the episode scheduler and the held-out
episodes (:mod:`~accd_gym.evals.episodes`), locally or over Ray
(:mod:`~accd_gym.evals.distributed`), the evaluation report (:mod:`~accd_gym.evals.evaluation`),
and what trains and then evaluates: the benchmark suite (:mod:`~accd_gym.evals.benchmark`) and
Ray Tune sweeps (:mod:`~accd_gym.evals.sweep`)."""
