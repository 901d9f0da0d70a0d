"""Design time: vehicle parameters, linear design models, LMI designs and their certificates.

Never imports fmpy or pythonfmu; the design file (``design_file.py``) is the only thing that
crosses to the FMU side.
"""
