"""A supplier's electric drive unit (EDU) as a pythonfmu FMI 2.0 Co-Simulation model.

It stands for a third-party EDU FMU on the virtual bench: the same physics as twinbench's
reference EDU (models/edu) but with the supplier's own variable names and units (speeds
in rpm, pedal in percent, powers in kW). The bench swaps it in through the port map of
systems/rls_v_supplier.toml; the orchestrator converts units from the declared
<UnitDefinitions>.

Physics (SI inside; the interface converts):
  T_avail = min(T_MotorMax, P_MotorMax / |w_m|)
  T_cmd   = pedal * T_avail, current loop tau * dT_m/dt = T_cmd - T_m, |T_m| <= T_avail
  J * dw_m/dt = T_m - T_in, gearbox i_Gear with eta_Gear against the power flow
  open differential (both shafts carry the same torque), side shafts as spring-dampers
  T_Shaft = c * (phi_l + phi_r)/2 + d * (w_m/i - (w_l + w_r)/2)
  P_Electric = T_m*w_m/eta_Motor motoring, T_m*w_m*eta_Motor generating
Integration: equal sub-steps of at most h_SubstepMax, semi-implicit (the twist sees the
updated motor speed), the current lag and the twist difference solved exactly per sub-step.

pythonfmu 0.7 cannot declare units, output dependencies or initial unknowns, so `to_xml`
below adds them to the model description it generates at build time
(tools/supplier_edu/build.py).
"""

import math
import uuid
from pathlib import Path
from xml.etree.ElementTree import Element, SubElement

from pythonfmu import DefaultExperiment, Fmi2Causality, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Status

RPM = math.pi / 30.0  # rad/s per rpm

# <Unit> definitions (FMI 2.0: value_SI = factor * value + offset), by unit name.
UNITS = {
    "1": {},
    "%": {"factor": "0.01"},
    "s": {"s": "1"},
    "rpm": {"s": "-1", "rad": "1", "factor": repr(RPM)},
    "N.m": {"kg": "1", "m": "2", "s": "-2"},
    "kW": {"kg": "1", "m": "2", "s": "-3", "factor": "1000"},
    "kg.m2": {"kg": "1", "m": "2"},
    "N.m/rad": {"kg": "1", "m": "2", "s": "-2", "rad": "-1"},
    "N.m.s/rad": {"kg": "1", "m": "2", "s": "-1", "rad": "-1"},
}

# name: (causality, unit, start, description). Outputs have no start.
PARAMETERS = [
    ("T_MotorMax", "N.m", 150.0, "Motor torque limit"),
    ("P_MotorMax", "kW", 200.0, "Motor mechanical power limit"),
    ("eta_Motor", "1", 0.9, "Motor and inverter efficiency"),
    ("i_Gear", "1", 17.86, "Gear ratio, motor speed / differential case speed"),
    ("eta_Gear", "1", 0.96, "Gearbox efficiency, against the power flow"),
    ("J_Motor", "kg.m2", 0.01, "Rotor inertia"),
    ("tau_Current", "s", 0.001, "Current (torque) loop time constant"),
    ("c_Shaft", "N.m/rad", 12000.0, "Torsional stiffness of each side shaft"),
    ("d_Shaft", "N.m.s/rad", 40.0, "Torsional damping of each side shaft"),
    ("n_WheelStart", "rpm", 151.97 / RPM, "Initial wheel speed; the motor starts at i_Gear times this"),
    ("h_SubstepMax", "s", 1e-4, "Largest internal integration step"),
]
INPUTS = [
    ("PedalPosition", "%", 0.0, "Torque request in percent of the available torque; negative: regenerative braking"),
    ("n_WheelLeft", "rpm", 0.0, "Left side shaft speed at the wheel"),
    ("n_WheelRight", "rpm", 0.0, "Right side shaft speed at the wheel"),
]
# name: (unit, depends on the speed inputs, description)
OUTPUTS = [
    ("T_ShaftLeft", "N.m", True, "Left side shaft torque, positive drives the wheel forward"),
    ("T_ShaftRight", "N.m", True, "Right side shaft torque, positive drives the wheel forward"),
    ("n_Motor", "rpm", False, "Motor speed"),
    ("T_Motor", "N.m", False, "Motor air-gap torque"),
    ("P_Electric", "kW", False, "Electric power from the battery, negative when generating"),
    ("P_Mechanical", "kW", False, "Motor shaft power"),
]
UNIT_OF = {n: u for n, u, *_ in PARAMETERS + INPUTS}
UNIT_OF.update({n: u for n, u, *_ in OUTPUTS})


class SupplierEdu(Fmi2Slave):
    author = "twinbench (a stand-in for a supplier)"
    description = "Supplier EDU: motor with torque/power limit and current lag, gearbox, open differential, side shafts"
    version = "1.0"
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=10.0, step_size=1e-3)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        # A GUID from the model source, so that a rebuild of the same model keeps it.
        self.guid = uuid.uuid5(uuid.NAMESPACE_URL, "twinbench-supplier-edu:" + Path(__file__).read_text())
        for name, unit, start, text in PARAMETERS:
            setattr(self, name, start)
            self.register_variable(Real(name, causality=Fmi2Causality.parameter,
                                        variability=Fmi2Variability.fixed, description=text))
        for name, unit, start, text in INPUTS:
            setattr(self, name, start)
            self.register_variable(Real(name, causality=Fmi2Causality.input,
                                        variability=Fmi2Variability.continuous, description=text))
        getters = {
            "T_ShaftLeft": self._shaft_torque,
            "T_ShaftRight": self._shaft_torque,
            "n_Motor": lambda: self.w_m / RPM,
            "T_Motor": lambda: self.t_m,
            "P_Electric": lambda: self._electric_power(self.t_m * self.w_m) / 1000.0,
            "P_Mechanical": lambda: self.t_m * self.w_m / 1000.0,
        }
        for name, unit, _, text in OUTPUTS:
            self.register_variable(Real(name, causality=Fmi2Causality.output,
                                        variability=Fmi2Variability.continuous, description=text,
                                        getter=getters[name]))
        self._init_state()

    # -- model ------------------------------------------------------------------------

    def _init_state(self):
        self.w_m = self.i_Gear * self.n_WheelStart * RPM  # motor speed [rad/s]
        self.t_m = 0.0  # motor torque [N.m]
        self.twist_mean = 0.0  # (phi_l + phi_r) / 2 [rad]
        self.twist_diff = 0.0  # phi_l - phi_r [rad]

    def _torque_limit(self, w_m):
        if w_m == 0.0:
            return self.T_MotorMax
        return min(self.T_MotorMax, self.P_MotorMax * 1000.0 / abs(w_m))

    def _electric_power(self, mechanical):
        return mechanical / self.eta_Motor if mechanical >= 0.0 else mechanical * self.eta_Motor

    def _shaft_torque(self):
        w_l = self.n_WheelLeft * RPM
        w_r = self.n_WheelRight * RPM
        return self.c_Shaft * self.twist_mean + self.d_Shaft * (self.w_m / self.i_Gear - 0.5 * (w_l + w_r))

    def enter_initialization_mode(self):
        self._init_state()

    def exit_initialization_mode(self):
        self._init_state()

    def do_step(self, current_time, step_size):
        n = max(math.ceil(step_size / self.h_SubstepMax), 1)
        h = step_size / n
        pedal = self.PedalPosition / 100.0
        w_wheel = 0.5 * (self.n_WheelLeft * RPM + self.n_WheelRight * RPM)
        ratio, eta_g, c, d = self.i_Gear, self.eta_Gear, self.c_Shaft, self.d_Shaft
        j, tau = self.J_Motor, self.tau_Current
        diff_decay = math.exp(-c / d * h)
        lag = math.exp(-h / tau)
        w_m, t_m, twist = self.w_m, self.t_m, self.twist_mean
        for _ in range(n):
            w_c = w_m / ratio
            t_out = 2.0 * (c * twist + d * (w_c - w_wheel))
            # Gearbox losses always take power away from the flow.
            t_in = t_out / (ratio * eta_g) if t_out * w_c >= 0.0 else t_out * eta_g / ratio
            w_m += h * (t_m - t_in) / j
            twist += h * (w_m / ratio - w_wheel)
            self.twist_diff *= diff_decay
            limit = self._torque_limit(w_m)
            command = pedal * limit
            t_m = min(max(command + (t_m - command) * lag, -limit), limit)
        self.w_m, self.t_m, self.twist_mean = w_m, t_m, twist
        if not (math.isfinite(w_m) and math.isfinite(twist)):
            self.log(f"state diverged at t = {current_time} s (n_Motor = {w_m / RPM} rpm)", Fmi2Status.error)
            return False
        return True

    # -- model description: units and output dependencies (not supported by pythonfmu 0.7) --

    def to_xml(self, model_options=dict()):
        root = super().to_xml(model_options)
        used = []
        index_of = {}
        for k, sv in enumerate(root.find("ModelVariables"), start=1):
            name = sv.get("name")
            index_of[name] = k
            unit = UNIT_OF.get(name)
            real = sv.find("Real")
            if unit is not None and real is not None:
                real.set("unit", unit)
                if unit not in used:
                    used.append(unit)
            if name == "PedalPosition":
                real.set("min", "-100")
                real.set("max", "100")
        defs = Element("UnitDefinitions")
        for unit in used:
            SubElement(SubElement(defs, "Unit", name=unit), "BaseUnit", UNITS[unit])
        # FMI 2.0 order: CoSimulation, UnitDefinitions, TypeDefinitions, LogCategories, ...
        position = list(root).index(root.find("CoSimulation")) + 1
        root.insert(position, defs)
        speeds = f"{index_of['n_WheelLeft']} {index_of['n_WheelRight']}"
        outputs = root.find("ModelStructure/Outputs")
        for unknown in outputs:
            name = list(root.find("ModelVariables"))[int(unknown.get("index")) - 1].get("name")
            feedthrough = next(f for n, _, f, _ in OUTPUTS if n == name)
            unknown.set("dependencies", speeds if feedthrough else "")
        # Outputs are calculated in initialization mode: they are initial unknowns (no
        # dependencies attribute: they may depend on every parameter and input).
        initial = SubElement(root.find("ModelStructure"), "InitialUnknowns")
        for unknown in outputs:
            SubElement(initial, "Unknown", index=unknown.get("index"))
        return root
