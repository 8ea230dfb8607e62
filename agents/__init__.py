"""Agents: LQR baselines, excitation signals, evaluation, the ``marine`` command line.

(Stable-Baselines3 training and the estimator ablation benchmarks arrive with later issues.)
"""
