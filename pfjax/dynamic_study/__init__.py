"""The kinematic-versus-dynamic comparison study (``studies/kinematic_vs_dynamic.py``): does the
robustness verdict of the kinematic slip studies survive a vehicle whose slip comes from tyre forces?

Modules: :mod:`~pfjax.dynamic_study.config` (the schema), :mod:`~pfjax.dynamic_study.arms` (the
arms' Monte Carlo study configs, the passenger-car scaling), :mod:`~pfjax.dynamic_study.designs`
(kinematic and dynamic LMI designs), :mod:`~pfjax.dynamic_study.throughput` (cost per rollout-step
of the kinematic, ST and STD models), :mod:`~pfjax.dynamic_study.runs` (running the arms and
writing the outputs), :mod:`~pfjax.dynamic_study.summary` and :mod:`~pfjax.dynamic_study.report`.
"""
