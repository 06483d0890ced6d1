"""smc: learn Sensory-Motor Contingencies from demonstrations and execute them.

Implements Stefanini et al., Robotics 13(4):58, 2024.
"""

__version__ = "0.1.0"
