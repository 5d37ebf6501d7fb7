"""A compiled FMI 2 co-simulation FMU written in C, no Python inside (tests and benchmark, issue 23).

The law: rate damping, ``tau_cmd = -kd J omega_BN_B`` [N m], with ``J`` the FMU parameter
``inertia_O_B[0..8]`` (row-major: a plant fact the loop sets) and ``kd`` [1/s]. What a Simulink or
Modelica export is: a shared library behind the FMI 2 C functions and a modelDescription.xml.
:func:`build` writes the C file, compiles it with the system C compiler and zips the FMU;
:class:`RateDamp` is the same law as a Python controller, written with the same operations in the
same order (the C is compiled with ``-ffp-contract=off``: no fused multiply-adds), so the two fly
the same trajectory bit for bit.
"""

from __future__ import annotations

import shutil
import subprocess
import zipfile
from pathlib import Path

from pydantic import Field

from stationbed.run.controller import Controller, ControllerParams

MODEL = "c_rate_damp"
KD_PER_S = 0.05  # 1/s, the FMU's start value of kd

#: value references: omega_BN_B[0..2] inputs 0..2, tau_cmd[0..2] outputs 3..5, kd 6, inertia_O_B 7..15
_C = r"""
#include <stdlib.h>
#include <string.h>
typedef struct { double w[3], tau[3], kd, J[9], time; } Inst;
static void start(Inst *s) { memset(s, 0, sizeof *s); s->kd = KD; }
void *fmi2Instantiate(const char *n, int t, const char *g, const char *r, const void *f, int v, int l) {
    Inst *s = malloc(sizeof *s); start(s); return s; }
void fmi2FreeInstance(void *c) { free(c); }
const char *fmi2GetTypesPlatform(void) { return "default"; }
const char *fmi2GetVersion(void) { return "2.0"; }
int fmi2SetupExperiment(void *c, int td, double tol, double t0, int sd, double t1) { ((Inst *)c)->time = t0; return 0; }
int fmi2EnterInitializationMode(void *c) { return 0; }
int fmi2ExitInitializationMode(void *c) { return 0; }
int fmi2Terminate(void *c) { return 0; }
int fmi2Reset(void *c) { start((Inst *)c); return 0; }
int fmi2SetDebugLogging(void *c, int on, size_t n, const char *const *cat) { return 0; }
int fmi2SetReal(void *c, const unsigned *vr, size_t n, const double *v) {
    Inst *s = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] < 3) s->w[vr[i]] = v[i];
        else if (vr[i] == 6) s->kd = v[i];
        else if (vr[i] >= 7 && vr[i] < 16) s->J[vr[i] - 7] = v[i];
        else return 3;
    }
    return 0;
}
int fmi2GetReal(void *c, const unsigned *vr, size_t n, double *v) {
    Inst *s = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] < 3) v[i] = s->w[vr[i]];
        else if (vr[i] < 6) v[i] = s->tau[vr[i] - 3];
        else if (vr[i] == 6) v[i] = s->kd;
        else if (vr[i] < 16) v[i] = s->J[vr[i] - 7];
        else return 3;
    }
    return 0;
}
int fmi2DoStep(void *c, double t, double h, int nosp) {
    Inst *s = c;
    const double *J = s->J, *w = s->w;
    for (int i = 0; i < 3; i++)
        s->tau[i] = -s->kd * (J[3 * i] * w[0] + J[3 * i + 1] * w[1] + J[3 * i + 2] * w[2]);
    s->time = t + h;
    return 0;
}
"""

_XML = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="{m}" guid="{{5c0a1e2d-0000-4000-8000-000000000023}}"
    generationTool="stationbed tests" variableNamingConvention="structured" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="{m}" canHandleVariableCommunicationStepSize="true"/>
  <ModelVariables>
{vars}
  </ModelVariables>
  <ModelStructure>
    <Outputs>
      <Unknown index="4"/><Unknown index="5"/><Unknown index="6"/>
    </Outputs>
  </ModelStructure>
</fmiModelDescription>
"""


def _variables() -> str:
    rows = []
    for i in range(3):
        rows.append(f'<ScalarVariable name="omega_BN_B[{i}]" valueReference="{i}" causality="input" '
                    'variability="continuous"><Real start="0.0"/></ScalarVariable>')
    for i in range(3):
        rows.append(f'<ScalarVariable name="tau_cmd[{i}]" valueReference="{3 + i}" causality="output" '
                    'variability="continuous" initial="calculated"><Real/></ScalarVariable>')
    rows.append(f'<ScalarVariable name="kd" valueReference="6" causality="parameter" variability="tunable">'
                f'<Real start="{KD_PER_S!r}"/></ScalarVariable>')
    for i in range(9):
        rows.append(f'<ScalarVariable name="inertia_O_B[{i}]" valueReference="{7 + i}" causality="parameter" '
                    'variability="fixed"><Real start="0.0"/></ScalarVariable>')
    return "\n".join("    " + r for r in rows)


def _stubs(code: str) -> str:
    """An error-returning definition of every other FMI 2 function FMPy loads (all must exist)."""
    from fmpy.fmi2 import FMU2Slave

    names = [n for n in dir(FMU2Slave) if n.startswith("fmi2") and f" {n}(" not in code and f"*{n}(" not in code]
    return "".join(f"int {n}() {{ return 3; }}\n" for n in names)


def compiler() -> str | None:
    """The system C compiler, or None."""
    return shutil.which("cc") or shutil.which("gcc")


def build(folder: Path, platform: str = "linux64") -> Path:
    """Compile the C FMU into ``folder/c_rate_damp.fmu`` (needs :func:`compiler`)."""
    folder.mkdir(parents=True, exist_ok=True)
    src = folder / f"{MODEL}.c"
    src.write_text(_C.replace("KD", repr(KD_PER_S)) + _stubs(_C))
    lib = folder / f"{MODEL}.so"
    subprocess.run([compiler(), "-shared", "-fPIC", "-O2", "-ffp-contract=off", "-o", str(lib), str(src)],
                   check=True, capture_output=True)
    fmu = folder / f"{MODEL}.fmu"
    with zipfile.ZipFile(fmu, "w") as z:
        z.writestr("modelDescription.xml", _XML.format(m=MODEL, vars=_variables()))
        z.write(lib, f"binaries/{platform}/{MODEL}.so")
    return fmu


class RateDampParams(ControllerParams):
    kd: float = Field(default=KD_PER_S, gt=0.0)  # 1/s


class RateDamp(Controller):
    """The C FMU's law in Python, the same operations in the same order."""

    name = "rate_damp"
    Params = RateDampParams

    def _reset(self, plant):
        self.J = [float(v) for v in plant.inertia_O_B.ravel()]

    def _update(self, t, meas):
        J, (w0, w1, w2), kd = self.J, meas.omega_BN_B.tolist(), self.params.kd
        return tuple(-kd * (J[3 * i] * w0 + J[3 * i + 1] * w1 + J[3 * i + 2] * w2) for i in range(3))
