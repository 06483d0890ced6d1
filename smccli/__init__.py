"""smc: learn Sensory-Motor Contingencies from demonstrations and execute them (Stefanini et al. 2024)."""

__version__ = "0.1.0"
