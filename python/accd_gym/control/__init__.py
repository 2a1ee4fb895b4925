"""Classical controllers: the :class:`~accd_gym.control.registry.Policy` interface and the
controllers by name (:mod:`~accd_gym.control.registry`), the built-in baselines (zero, random,
guidance: :mod:`~accd_gym.control.baselines`) and the linearized dynamics with the LQR baseline
(:mod:`~accd_gym.control.lqr`)."""
