"""The optimal-control problem and its solvers (``eq:optimization``, ``eq:mpc``).

One FHOCP (:mod:`~controllers.ocp.fhocp`) for every control law, with a pluggable reference
(:mod:`~controllers.ocp.reference`): the paper's set-point
(:mod:`~controllers.laws.paper.reference`) and the tracking law's artificial steady state
(:mod:`~controllers.laws.tracking.reference`, with :mod:`~controllers.ocp.steady_state`);
their NLP formulations (single shooting with exact derivatives,
:mod:`~controllers.ocp.shooting`, :mod:`~controllers.ocp.nlp_single_shooting`,
:mod:`~controllers.laws.tracking.nlp`; the multiple-shooting baseline), the one judge of every
answer and its status (:mod:`~controllers.ocp.fhocp_result`,
:mod:`~controllers.ocp.solve_status`), the solver settings, and the controllers that solve
them each step (:mod:`~controllers.laws.paper.mpc`, :mod:`~controllers.laws.tracking.mpc`) with
the reference governor (:mod:`~controllers.laws.paper.governor`).
"""
