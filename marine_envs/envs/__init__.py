"""Gymnasium environments: a batched simulation core with single and native vector front ends."""

from .base import MarineEnv, MarineVectorEnv
from .core import Simulator, Task
from .usv import USVEnv, USVVectorEnv

__all__ = ["MarineEnv", "MarineVectorEnv", "Simulator", "Task", "USVEnv", "USVVectorEnv"]
