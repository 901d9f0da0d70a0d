"""latobs: vehicle lateral-dynamics observers from published LMI designs, packaged as FMI 2.0 FMUs.

Pipeline (data flows one way): parameters -> linear design model -> LMI design -> certificate
-> design file (``latobs.synthesis``) -> FMU (``latobs.fmu_src`` runtime, ``latobs.packaging``)
-> validation (``latobs.validation``, fmpy).
"""
__version__ = "0.1.0"
