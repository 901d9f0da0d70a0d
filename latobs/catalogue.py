"""The catalogue: one entry per FMU that ``latobs build`` makes, the one place an FMU is declared.

Each entry names the FMU, its paper, default vehicle, design, certificate, model file, runtime, C
model and emitter, the plant it runs beside, its scenarios and its campaign. Every registry of
the other layers (``synthesis.designs.DESIGNS``, ``packaging.OBSERVERS``/``PLANTS``,
``cbackend.EMITTERS``, ``pipeline.REFERENCE_EXPERIMENTS``, ``latobs validate``'s default
observers, ``validation.metrics.REFERENCE_SIGNALS``) is derived from it. Modules are dotted names
(``MODULES``, resolved lazily by :func:`resolve`): this module imports nothing but the standard
library, so every layer may read it.
"""
from __future__ import annotations

from dataclasses import dataclass
from importlib import import_module

__all__ = ["MODULES", "Entry", "Reference", "ENTRIES", "PART_EMITTERS", "OBSERVERS", "PLANTS", "get", "resolve", "default_observers"]

#: Every module the catalogue points to, by role, in one place: renaming a module is an edit here.
#: ``{m[KEY]}`` in an entry's strings below stands for ``MODULES[KEY]``.
MODULES = {
    # design time (latobs.synthesis): the design of each paper, its certificate
    "design_000": "latobs.synthesis.sideslip_bank_observer",
    "design_000_h2": "latobs.synthesis.sideslip_bank_observer_h2",
    "design_001": "latobs.synthesis.lateral_interval_observer",
    "design_002": "latobs.synthesis.sideslip_fixed_order_estimator",
    "design_kalman": "latobs.synthesis.sideslip_kalman_filter",
    "design_003": "latobs.synthesis.motorcycle_fault_observer",
    "design_003_measured": "latobs.synthesis.motorcycle_fault_observer_lpv",
    "certificate": "latobs.synthesis.certificate",
    "plant_data": "latobs.packaging",
    # runtime (latobs.fmu_src): the paper's equations, the FMU's declarations, the citations
    "runtime_000": "latobs.fmu_src.sideslip_bank_observer",
    "runtime_001": "latobs.fmu_src.lateral_interval_observer",
    "runtime_002": "latobs.fmu_src.sideslip_fixed_order_estimator",
    "runtime_kalman": "latobs.fmu_src.sideslip_kalman_filter",
    "runtime_003": "latobs.fmu_src.motorcycle_fault_observer",
    "runtime_car": "latobs.fmu_src.car_plant",
    "runtime_motorcycle": "latobs.fmu_src.motorcycle_plant",
    "models": "latobs.fmu_src.models",
    "papers": "latobs.fmu_src.papers",
    # native C backend: the emitters (latobs.cbackend) of the C models (fmu_src/c/*.c)
    "emitter_000": "latobs.cbackend.sideslip_bank_observer",
    "emitter_001": "latobs.cbackend.lateral_interval_observer",
    "emitter_002": "latobs.cbackend.sideslip_fixed_order_estimator",
    "emitter_kalman": "latobs.cbackend.sideslip_kalman_filter",
    "emitter_003": "latobs.cbackend.motorcycle_fault_observer",
    "emitter_car": "latobs.cbackend.car_plant",
    "emitter_motorcycle": "latobs.cbackend.motorcycle_plant",
    "emitter_signals": "latobs.cbackend.signal_source",
}


@dataclass(frozen=True)
class Reference:
    """The reference experiment an FMU carries (FMI-LS-REF, ``latobs check``): the first ``seconds``
    of its validation ``scenario`` with the scenario fields ``overrides`` (``note`` says why)."""
    scenario: str
    seconds: float
    overrides: tuple[tuple[str, object], ...] = ()
    note: str = ""


@dataclass(frozen=True)
class Entry:
    """One FMU. Dotted names are ``module`` or ``module:attribute`` (:func:`resolve`).

    name             the FMU's name: its FMI modelIdentifier for the default vehicle (``NAME_V`` for another)
    kind             "observer" (built from a design file) or "plant" (from a vehicle's parameters)
    paper            the paper it implements ("000".."003"; None: latobs's own plant model)
    citation         the publication, ``papers:CONSTANT`` (the one its model file declares)
    default_vehicle  the vehicle parameter set it is built for by default
    description      one line, as ``latobs list`` shows it
    options          ``module:Class`` of its design options, called ``Class(name=..., **option_args)``
    option_args      the options that make this FMU (the variants of one paper's design differ here)
    design           ``module:function(vehicle, options)``, the LMI design
    to_dict          ``module:function(result)`` -> the design dict (None: ``design`` returns it)
    certificate      ``module:function(data)`` -> its certificate's checks
    data             plants: ``module:function(vehicle)`` -> the plant data file
    model            the model file ``latobs.fmu_src.models.<model>`` (its ``SPEC``: variables, runtime)
    runtime          ``module:Class`` the pythonfmu backend runs (the model file's ``SPEC.runtime``)
    c_model          the C source of the native backend, in ``fmu_src/c`` (the emitter's ``SOURCE``)
    emitter          the module writing the C model's data header
    plant            observers: the plant FMU it is validated beside
    reference        its reference experiment
    validate         run by ``latobs validate`` by default on its plant's scenarios
    campaign         the shipped campaign it belongs to (``latobs/campaigns/<campaign>.toml``)
    truth            {estimated quantity: the plant's bus signal it is scored against}, when not its own name
    noise            plants: {measured signal: (std, bias)} in SI units, the sensors of ``latobs validate --noise``
    steer            plants: its steering input (scaled by a campaign's ``steer_scale``)
    build_seconds    rough seconds of its cold build on the 2-core reference machine (design,
                     certificate, compilations, reference run): parallel builds start the longest first
    """
    name: str
    kind: str
    paper: str | None
    citation: str | None
    default_vehicle: str
    description: str
    model: str
    runtime: str
    c_model: str
    emitter: str
    reference: Reference
    options: str | None = None
    option_args: tuple[tuple[str, object], ...] = ()
    design: str | None = None
    to_dict: str | None = None
    certificate: str | None = None
    data: str | None = None
    plant: str | None = None
    validate: bool = False
    campaign: str | None = None
    truth: tuple[tuple[str, str], ...] = ()
    noise: tuple[tuple[str, tuple[float, float]], ...] = ()
    steer: str | None = None
    build_seconds: float = 10.0

    @property
    def model_module(self) -> str:
        """The model file's module name in ``latobs.fmu_src.models``."""
        return self.model.rsplit(".", 1)[-1]

    @property
    def emitter_module(self) -> str:
        """The emitter's module name in ``latobs.cbackend``."""
        return self.emitter.rsplit(".", 1)[-1]


def _m(text: str) -> str:
    return text.format(m=MODULES)


_SECONDS = 2.0          # 401 rows at the default step of 5 ms: a few tens of kB in an FMU
_BANK = ((0.0, 0.0), (0.5, 0.0), (0.5, 2.0), (8.0, 2.0), (12.0, 5.0), (18.0, 5.0), (18.0, -2.0), (22.0, -2.0),
         (26.0, 0.0))
_BANK_BRAKING = Reference("bank-braking", _SECONDS, (("bank_knots_deg", _BANK), ("t_brake", 1.0)),
                          "the 2 deg bank step at 0.5 s and the braking from 1 s")
_LANE_CHANGE = Reference("double-lane-change", _SECONDS, (("t_start", 0.2),), "the lane change from 0.2 s")
_MOTORCYCLE = Reference("motorcycle-lane-change", _SECONDS,
                        (("t_rise", 0.0), ("t_first", 0.2), ("pulse", 0.8), ("t_second", 1.1)),
                        "the speed rise and both torque pulses (0.8 s each) within the first 2 s")
_CG = (("vy", "vy_cg"), ("beta", "beta_cg"))     # the bicycle model's states are the CG's


def _paper_000(name: str, switching: str, faithful: bool, description: str, build_seconds: float,
               design: str = "design_000", options: str = "DesignOptions") -> Entry:
    """The four paper-000 FMUs: one model file, runtime and C model, other design options; ``design``:
    the module of their gains (Theorem 2, or the robust-H2 departure), ``options`` its options class."""
    return Entry(
        name, "observer", "000", _m("{m[papers]}:MENHOUR_2014"), "sedan", description,
        model=_m("{m[models]}.sideslip_bank_observer"), runtime=_m("{m[runtime_000]}:SwitchedPIObserver"),
        c_model="sideslip_bank_observer.c", emitter=_m("{m[emitter_000]}"), reference=_BANK_BRAKING,
        options=f"{MODULES[design]}:{options}",
        option_args=(("switching", switching), ("faithful", faithful)),
        design=MODULES[design] + ":design", to_dict=MODULES[design] + ":to_design_dict",
        certificate=_m("{m[certificate]}.sideslip_bank_observer:certify"), plant="CarPlant", validate=True, campaign="robustness-000",
        build_seconds=build_seconds)


#: every FMU of ``latobs build``: the observers, then the plants
ENTRIES: tuple[Entry, ...] = (
    _paper_000("SideslipBankObserver", "speed", False,
               "switched PI observer, sideslip + road bank angle, speed modes 36/63/90 km/h (eq. 25), model at the "
               "measured speed with the axle forces relaxed as the tires' (latobs), gains robust-H2 over a +-15 % "
               "cornering-stiffness box (latobs), valid flag with "
               "integral freeze", 8.0, "design_000_h2", "H2Options"),
    _paper_000("SideslipBankObserverTire", "tire", False,
               "switched H-inf PI observer, sideslip + road bank angle, tire modes C1 / C2 (secant of the tire curve) "
               "at alpha* = 0.5 deg (eq. 27), robust to model error, valid flag with integral freeze", 9.0),
    _paper_000("SideslipBankObserverPaper", "speed", True,
               "the paper's speed-mode design as printed, for reproduction: LMI (20) + pole region only, each mode "
               "at its grid speed (eq. 25 literally)", 5.0),
    _paper_000("SideslipBankObserverTirePaper", "tire", True,
               "the paper's tire-mode design as printed, for reproduction: LMI (20) + pole region only on the grid "
               "speeds 36/63/90 km/h (eq. 27)", 6.0),
    Entry("LateralIntervalObserver", "observer", "001", _m("{m[papers]}:IFQIR_2020"), "sedan",
          "switched interval observer: guaranteed bounds of lateral velocity, sideslip, yaw rate and axle "
          "forces for cornering stiffnesses in a +-20 % box, speed modes 11.5/14.5/18 m/s (Theorem 1)",
          model=_m("{m[models]}.lateral_interval_observer"), runtime=_m("{m[runtime_001]}:IntervalObserver"),
          c_model="lateral_interval_observer.c", emitter=_m("{m[emitter_001]}"),
          reference=Reference("double-lane-change-15", _SECONDS, (("t_start", 0.2),), "the lane change from 0.2 s"),
          options=_m("{m[design_001]}:DesignOptions"), design=_m("{m[design_001]}:design"),
          to_dict=_m("{m[design_001]}:to_design_dict"), certificate=_m("{m[certificate]}.lateral_interval_observer:certify"),
          plant="CarPlant", campaign="robustness-001", truth=_CG, build_seconds=7.0),
    Entry("SideslipFixedOrderEstimator", "observer", "002", _m("{m[papers]}:DELIBASI_2014"), "delibasi",
          "fixed-order robust H-inf sideslip estimator beta^ = (y/x) r from the yaw rate alone, one filter for "
          "the whole (Cf, Cr, v) box, Lemma 5 + certified polish (Delibasi 2014)",
          model=_m("{m[models]}.sideslip_fixed_order_estimator"), runtime=_m("{m[runtime_002]}:TfEstimator"),
          c_model="sideslip_fixed_order_estimator.c", emitter=_m("{m[emitter_002]}"), reference=Reference("w1-steer", _SECONDS),
          options=_m("{m[design_002]}:DesignOptions"), option_args=(("scheduled", False),),
          design=_m("{m[design_002]}:design_for_vehicle"), to_dict=_m("{m[design_002]}:to_design_dict"),
          certificate=_m("{m[certificate]}.sideslip_fixed_order_estimator:certify"), plant="CarPlant", campaign="robustness-002",
          truth=_CG[1:], build_seconds=12.0),
    Entry("SideslipFixedOrderEstimatorScheduled", "observer", "002", _m("{m[papers]}:DELIBASI_2014"), "mbds_250lm",
          "speed-scheduled fixed-order robust H-inf sideslip estimator: one Lemma 5 design per speed band, "
          "switched on vx (extension of paper 002)",
          model=_m("{m[models]}.sideslip_fixed_order_estimator_scheduled"),
          runtime=_m("{m[runtime_002]}:TfEstimator"), c_model="sideslip_fixed_order_estimator.c", emitter=_m("{m[emitter_002]}"),
          reference=_LANE_CHANGE, options=_m("{m[design_002]}:DesignOptions"), option_args=(("scheduled", True),),
          design=_m("{m[design_002]}:design_for_vehicle"), to_dict=_m("{m[design_002]}:to_design_dict"),
          certificate=_m("{m[certificate]}.sideslip_fixed_order_estimator:certify"), plant="CarPlant", campaign="robustness-002",
          truth=_CG[1:], build_seconds=40.0),
    Entry("SideslipKalmanFilter", "observer", "002", _m("{m[papers]}:LEANZA_2021"), "mbds_250lm",
          "baseline peer of paper 002: the linear bicycle-model Kalman filter of the MBDS dataset's authors "
          "(measurements ay and yaw rate), noise tuned on the record's t < 425 s",
          model=_m("{m[models]}.sideslip_kalman_filter"), runtime=_m("{m[runtime_kalman]}:KalmanObserver"),
          c_model="sideslip_kalman_filter.c", emitter=_m("{m[emitter_kalman]}"), reference=_LANE_CHANGE,
          options=_m("{m[design_kalman]}:DesignOptions"), design=_m("{m[design_kalman]}:design"),
          certificate=_m("{m[certificate]}.sideslip_kalman_filter:certify"), plant="CarPlant", campaign="robustness-002",
          truth=_CG, build_seconds=5.0),
    Entry("MotorcycleFaultObserver", "observer", "003", _m("{m[papers]}:ICHALAL_2017"), "sharp_motorcycle",
          "H-inf observer of a motorcycle's roll angle and rider torque at the measured speed: roll angle as a "
          "state, PMI torque, one Lyapunov matrix for all speeds 7.5..32.5 m/s (paper 003 extended)",
          model=_m("{m[models]}.motorcycle_fault_observer"), runtime=_m("{m[runtime_003]}:MotorcycleFaultObserver"),
          c_model="motorcycle_fault_observer.c", emitter=_m("{m[emitter_003]}"), reference=_MOTORCYCLE,
          options=_m("{m[design_003_measured]}:DesignOptions"), design=_m("{m[design_003_measured]}:design"),
          certificate=_m("{m[certificate]}.motorcycle_fault_observer:certify"),
          plant="MotorcyclePlant", validate=True, campaign="robustness-003", build_seconds=9.0),
    Entry("MotorcycleFaultObserverPaper", "observer", "003", _m("{m[papers]}:ICHALAL_2017"), "sharp_motorcycle",
          "the paper's switched H-inf PI observer as printed, for reproduction: roll angle and rider torque as "
          "unknown inputs, one frozen model and Lyapunov matrix per grid speed 10..30 m/s, LMIs (20)-(23) corrected",
          model=_m("{m[models]}.motorcycle_fault_observer"), runtime=_m("{m[runtime_003]}:MotorcycleFaultObserver"),
          c_model="motorcycle_fault_observer.c", emitter=_m("{m[emitter_003]}"), reference=_MOTORCYCLE,
          options=_m("{m[design_003]}:DesignOptions"), design=_m("{m[design_003]}:design"),
          to_dict=_m("{m[design_003]}:to_design_dict"), certificate=_m("{m[certificate]}.motorcycle_fault_observer:certify"),
          plant="MotorcyclePlant", validate=True, campaign="robustness-003", build_seconds=8.0),
    Entry("CarPlant", "plant", None, None, "sedan",
          "two-track car with roll, nonlinear tires and load transfer, on a banked road",
          model=_m("{m[models]}.car_plant"), runtime=_m("{m[runtime_car]}:CarPlantModel"), c_model="car_plant.c",
          emitter=_m("{m[emitter_car]}"), reference=_BANK_BRAKING, data=_m("{m[plant_data]}:plant_data"),
          # typical automotive-grade inertial and steering sensors
          noise=(("yaw_rate", (0.002, 0.001)),       # rad/s
                 ("roll_angle", (0.002, 0.0)),       # rad
                 ("roll_rate", (0.003, 0.0005)),     # rad/s
                 ("delta", (0.0005, 0.0)),           # rad (road wheel)
                 ("vx", (0.05, 0.0))),               # m/s
          steer="delta", build_seconds=6.0),
    Entry("MotorcyclePlant", "plant", "003", _m("{m[papers]}:SHARP_1971"), "sharp_motorcycle",
          "Sharp's motorcycle (1971), its equations derived for the vehicle at build time",
          model=_m("{m[models]}.motorcycle_plant"), runtime=_m("{m[runtime_motorcycle]}:MotorcyclePlantModel"),
          c_model="motorcycle_plant.c", emitter=_m("{m[emitter_motorcycle]}"), reference=_MOTORCYCLE,
          data=_m("{m[plant_data]}:plant_data"),
          # paper 003, figure 3: noisy steer angle, yaw rate and roll rate; zero-mean (an IMU and a
          # steering encoder, after the usual bias calibration)
          noise=(("steer_angle", (0.001, 0.0)),      # rad (encoder)
                 ("yaw_rate", (0.005, 0.0)),         # rad/s
                 ("roll_rate", (0.005, 0.0)),        # rad/s
                 ("vx", (0.05, 0.0))),               # m/s
          steer="rider_torque", build_seconds=8.0),
)

#: C models that are parts of other artefacts, not FMUs of ``latobs build``: {model file: emitter}
#: (the SSP export's ``ScenarioSignals`` source, built per scenario by ``latobs.ssp``)
PART_EMITTERS: dict[str, str] = {"signal_source": _m("{m[emitter_signals]}")}

_BY_NAME = {e.name: e for e in ENTRIES}
#: the observer FMUs (built from a design file), in catalogue order
OBSERVERS: tuple[str, ...] = tuple(e.name for e in ENTRIES if e.kind == "observer")
#: the plant FMUs (built from a vehicle's parameters)
PLANTS: tuple[str, ...] = tuple(e.name for e in ENTRIES if e.kind == "plant")


def get(name: str) -> Entry:
    """The entry of the FMU ``name``; KeyError naming the known FMUs."""
    try:
        return _BY_NAME[name]
    except KeyError:
        raise KeyError(f"unknown FMU {name!r}; known: {', '.join(_BY_NAME)}") from None


def resolve(dotted: str):
    """The object a dotted name points to: ``package.module`` or ``package.module:attribute``."""
    module, _, attribute = dotted.partition(":")
    obj = import_module(module)
    for part in filter(None, attribute.split(".")):
        obj = getattr(obj, part)
    return obj


def default_observers(plant: str) -> list[str]:
    """The observers ``latobs validate`` runs by default on a scenario of ``plant``."""
    return [e.name for e in ENTRIES if e.kind == "observer" and e.plant == plant and e.validate]
