"""Classical controllers: the built-in baselines (zero, random, guidance:
:mod:`~accd_gym.control.baselines`) and the linearized dynamics with the LQR baseline
(:mod:`~accd_gym.control.lqr`)."""
