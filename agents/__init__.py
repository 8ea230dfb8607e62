"""Agents: LQR baselines, Stable-Baselines3 agents, one evaluation path, the estimator
benchmark grid, excitation signals, the source documents' experiments and the ``marine``
command line.

* :mod:`agents.lqr`: discrete/continuous LQR of any vehicle's task, on sensors, state or estimate;
* :mod:`agents.sb3`: SB3 training on the native batched env, RL-Zoo-style hyperparameters;
* :mod:`agents.policies`: every policy by name, one name a policy (the do-nothing baseline is
  ``nominal``);
* :mod:`agents.evaluation`: episodes with fixed seeds scored on the task's quadratic cost, RMS
  errors in physical units, actuator usage and estimation error, behind any estimator of
  :mod:`estimators.registry`;
* :mod:`agents.benchmark`: ``marine bench``, the vehicles x estimators x seas x sensors x
  controllers x seeds grid (``grid``), run locally or on Ray (``run``), and its tables, figures
  and HTML page (``report``);
* :mod:`agents.reproduce`: the source documents' experiments; :mod:`agents.cli`: ``marine``, one
  module a command.
"""
