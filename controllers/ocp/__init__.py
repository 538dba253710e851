"""The optimal-control problem and its solvers (``eq:optimization``, ``eq:mpc``).

The paper's FHOCP (:mod:`~controllers.ocp.fhocp`) and the tracking law's
(:mod:`~controllers.ocp.fhocp_tracking`, with the artificial steady state of
:mod:`~controllers.ocp.steady_state`), their NLP formulations (single shooting with exact
derivatives, :mod:`~controllers.ocp.shooting`, :mod:`~controllers.ocp.nlp_single_shooting`,
:mod:`~controllers.ocp.nlp_tracking`; the multiple-shooting baseline), their one answer check
and status (:mod:`~controllers.ocp.fhocp_result`, :mod:`~controllers.ocp.solve_status`), the
solver settings, and the control laws that solve them each step
(:mod:`~controllers.ocp.paper_mpc`, :mod:`~controllers.ocp.tracking_mpc`) with the reference
governor (:mod:`~controllers.ocp.governor`).
"""
