"""The certificates and the design (paper section IV): the theorem's quantities and checks.

:mod:`~controllers.certification.bounds` (the gate and contraction bounds of
``th:stability-bonassi``, ``lem:Vs``, ``lem:Vo``), :mod:`~controllers.certification.
certificates` (every quantity of ``th:feasibility-stability`` for one model and design),
the observer gains (:mod:`~controllers.certification.observer_gains`,
:mod:`~controllers.certification.gain_design`), the design arguments
(:mod:`~controllers.certification.design`), the tracking law's hypotheses
(:mod:`~controllers.laws.tracking.checks`), the verdict in the user's words
(:mod:`~controllers.certification.diagnosis`) and the measured prediction error of the
uncertified mode (:mod:`~controllers.certification.prediction_error`).
"""
