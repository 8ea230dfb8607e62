"""Estimators: filters, observers and identifiers as Gymnasium wrappers, and mismatch diagnosis.

Empty in this release: the Kalman, adaptive Kalman and quantized-signal PD observer arrive with
the estimators issues. It imports ``marine_envs`` only, never ``agents`` (ARCHITECTURE.md).
"""
