"""The publications the FMU models implement (``ModelSpec.paper``; each FMU's datasheet cites its own)."""
from .spec import Paper

MENHOUR_2014 = Paper(
    ("Lghani Menhour", "Damien Koenig", "Brigitte d'Andréa-Novel"),
    "Continuous-time switched H-infinity proportional-integral observer: application for sideslip and road "
    "bank angles estimation", "13th European Control Conference (ECC 2014), Strasbourg, pp. 2358-2363", 2014,
    "10.1109/ECC.2014.6862402")
IFQIR_2020 = Paper(
    ("Sara Ifqir", "Dalil Ichalal", "Naïma Aït Oufroukh", "Saïd Mammar"),
    "Vehicle lateral velocity and lateral tire-road forces estimation based on switched interval observers",
    "2020 American Control Conference (ACC 2020), Denver, pp. 3023-3028", 2020, "10.23919/ACC45564.2020.9147793")
DELIBASI_2014 = Paper(
    ("Akın Delibaşı",), "Fixed-order robust H-infinity estimator design for side-slip angle of vehicle",
    "Hindawi, research article", 2014)
ICHALAL_2017 = Paper(
    ("Dalil Ichalal", "Naïma Ait Oufroukh", "Pierre-Marie Damon", "Hichem Arioui", "Saïd Mammar"),
    "PI observer robust fault estimation for motorcycle lateral dynamics", "IEEE conference paper", 2017)
LEANZA_2021 = Paper(
    ("Antonio Leanza", "Giulio Reina", "José-Luis Blanco-Claraco"),
    "A factor-graph-based approach to vehicle sideslip angle estimation", "Sensors 21(16):5409", 2021,
    "10.3390/s21165409")
SHARP_1971 = Paper(
    ("R. S. Sharp",), "The stability and control of motorcycles",
    "Journal of Mechanical Engineering Science 13(5), pp. 316-329", 1971)
