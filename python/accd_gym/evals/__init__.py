"""Evaluating policies: loading any policy (:mod:`~accd_gym.evals.policies`), the held-out
episodes (:mod:`~accd_gym.evals.episodes`), locally or over Ray
(:mod:`~accd_gym.evals.distributed`), the evaluation report (:mod:`~accd_gym.evals.evaluation`),
and what trains and then evaluates: the benchmark suite (:mod:`~accd_gym.evals.benchmark`) and
Ray Tune sweeps (:mod:`~accd_gym.evals.sweep`)."""
