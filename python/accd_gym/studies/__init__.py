"""Open-loop tether studies: the paper's section 4 cases (:mod:`~accd_gym.studies.study`), the
studies past the paper (:mod:`~accd_gym.studies.fidelity`), the settling tether
(:mod:`~accd_gym.studies.settle`), and the runner behind ``accd-gym study``
(:mod:`~accd_gym.studies.runner`)."""
