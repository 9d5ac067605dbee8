/* rc_thermal.c - first-order thermal RC node as an FMI 2.0 co-simulation FMU.
 *
 *   c_j_k * dT/dt = heat_w - (T - t_ambient_c) / r_k_w
 *   outputs: t_c = T, heat_loss_w = (T - t_ambient_c) / r_k_w
 *
 * doStep integrates with n_substeps classical RK4 steps (inputs held), and
 * fails with fmi2Error when T exceeds t_max_c or becomes non-finite (used by
 * the shevsim tests of doStep error reporting). Supports get/set FMU state.
 * Part of shevsim (fmus/src/rc_thermal); built by shevsim.fmu.build.build_c_fmu.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"

#define VR_C 0
#define VR_R 1
#define VR_T0 2
#define VR_TMAX 3
#define VR_NSUB 4
#define VR_HEAT 5
#define VR_TAMB 6
#define VR_T 7
#define VR_LOSS 8

typedef struct {
    double c_j_k, r_k_w, t0_c, t_max_c;
    int n_substeps;
    double heat_w, t_ambient_c;
    double T;
    double time;
    int initialized;
} State;

typedef struct {
    State s;
    fmi2CallbackFunctions cb;
    char name[128];
} Instance;

static void logmsg(Instance *inst, fmi2Status status, const char *msg) {
    if (inst->cb.logger)
        inst->cb.logger(inst->cb.componentEnvironment, inst->name, status, "logStatusError", "%s", msg);
}

static double deriv(const State *s, double T) {
    return (s->heat_w - (T - s->t_ambient_c) / s->r_k_w) / s->c_j_k;
}

static double getvr(const State *s, fmi2ValueReference vr, int *ok) {
    *ok = 1;
    switch (vr) {
    case VR_C: return s->c_j_k;
    case VR_R: return s->r_k_w;
    case VR_T0: return s->t0_c;
    case VR_TMAX: return s->t_max_c;
    case VR_HEAT: return s->heat_w;
    case VR_TAMB: return s->t_ambient_c;
    case VR_T: return s->T;
    case VR_LOSS: return (s->T - s->t_ambient_c) / s->r_k_w;
    default: *ok = 0; return 0.0;
    }
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)fmuResourceLocation; (void)visible; (void)loggingOn;
    if (fmuType != fmi2CoSimulation) return NULL;
    if (!fmuGUID || strcmp(fmuGUID, "{6f1d6a52-3b5e-4c1f-9a55-2f0c8e7b9a11}") != 0) return NULL;
    Instance *inst = (Instance *)calloc(1, sizeof(Instance));
    if (!inst) return NULL;
    if (functions) inst->cb = *functions;
    strncpy(inst->name, instanceName ? instanceName : "rc_thermal", sizeof(inst->name) - 1);
    inst->s.c_j_k = 5000.0; inst->s.r_k_w = 0.02; inst->s.t0_c = 25.0; inst->s.t_max_c = 500.0;
    inst->s.n_substeps = 10; inst->s.heat_w = 0.0; inst->s.t_ambient_c = 25.0; inst->s.T = 25.0;
    return (fmi2Component)inst;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) {
    (void)c; (void)on; (void)n; (void)cat; return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDef, fmi2Real tol, fmi2Real t0,
                               fmi2Boolean stopDef, fmi2Real tStop) {
    (void)tolDef; (void)tol; (void)stopDef; (void)tStop;
    ((Instance *)c)->s.time = t0; return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (!(inst->s.c_j_k > 0) || !(inst->s.r_k_w > 0) || inst->s.n_substeps < 1) {
        logmsg(inst, fmi2Error, "invalid parameters: need c_j_k > 0, r_k_w > 0, n_substeps >= 1");
        return fmi2Error;
    }
    inst->s.T = inst->s.t0_c;
    inst->s.initialized = 1;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }

fmi2Status fmi2Reset(fmi2Component c) {
    Instance *inst = (Instance *)c;
    State s0 = {5000.0, 0.02, 25.0, 500.0, 10, 0.0, 25.0, 25.0, 0.0, 0};
    inst->s = s0;
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    Instance *inst = (Instance *)c;
    for (size_t i = 0; i < nvr; i++) {
        int ok; value[i] = getvr(&inst->s, vr[i], &ok);
        if (!ok) { logmsg(inst, fmi2Error, "fmi2GetReal: unknown value reference"); return fmi2Error; }
    }
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    Instance *inst = (Instance *)c;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] != VR_NSUB) return fmi2Error;
        value[i] = inst->s.n_substeps;
    }
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    (void)c; (void)vr; (void)value; return nvr ? fmi2Error : fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    (void)c; (void)vr; (void)value; return nvr ? fmi2Error : fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    Instance *inst = (Instance *)c;
    State *s = &inst->s;
    for (size_t i = 0; i < nvr; i++) {
        switch (vr[i]) {
        case VR_C: s->c_j_k = value[i]; break;
        case VR_R: s->r_k_w = value[i]; break;
        case VR_T0: s->t0_c = value[i]; break;
        case VR_TMAX: s->t_max_c = value[i]; break;
        case VR_HEAT: s->heat_w = value[i]; break;
        case VR_TAMB: s->t_ambient_c = value[i]; break;
        default: logmsg(inst, fmi2Error, "fmi2SetReal: value reference not settable"); return fmi2Error;
        }
    }
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
    Instance *inst = (Instance *)c;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] != VR_NSUB) return fmi2Error;
        inst->s.n_substeps = value[i];
    }
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
    (void)c; (void)vr; (void)value; return nvr ? fmi2Error : fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    (void)c; (void)vr; (void)value; return nvr ? fmi2Error : fmi2OK;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    State *copy = (State *)malloc(sizeof(State));
    if (!copy) return fmi2Error;
    *copy = ((Instance *)c)->s;
    *FMUstate = (fmi2FMUstate)copy;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    if (!FMUstate) return fmi2Error;
    ((Instance *)c)->s = *(State *)FMUstate;
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    (void)c;
    if (FMUstate && *FMUstate) { free(*FMUstate); *FMUstate = NULL; }
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *size) {
    (void)c; (void)s; *size = sizeof(State); return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte ser[], size_t size) {
    (void)c;
    if (size < sizeof(State)) return fmi2Error;
    memcpy(ser, s, sizeof(State)); return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte ser[], size_t size, fmi2FMUstate *s) {
    (void)c;
    if (size < sizeof(State)) return fmi2Error;
    State *copy = (State *)malloc(sizeof(State));
    if (!copy) return fmi2Error;
    memcpy(copy, ser, sizeof(State));
    *s = (fmi2FMUstate)copy;
    return fmi2OK;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real du[], fmi2Real dz[]) {
    (void)c; (void)u; (void)nu; (void)z; (void)nz; (void)du; (void)dz; return fmi2Error;
}

/* ---- co-simulation ---- */
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)c; (void)vr; (void)nvr; (void)order; (void)value; return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)c; (void)vr; (void)nvr; (void)order; (void)value; return fmi2Error;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    (void)noSetPrior;
    Instance *inst = (Instance *)c;
    State *s = &inst->s;
    if (!(h > 0)) { logmsg(inst, fmi2Error, "doStep: step size must be > 0"); return fmi2Error; }
    double dt = h / s->n_substeps;
    double T = s->T;
    for (int i = 0; i < s->n_substeps; i++) {
        double k1 = deriv(s, T);
        double k2 = deriv(s, T + 0.5 * dt * k1);
        double k3 = deriv(s, T + 0.5 * dt * k2);
        double k4 = deriv(s, T + dt * k3);
        T += dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
    }
    if (!isfinite(T) || T > s->t_max_c) {
        char msg[200];
        snprintf(msg, sizeof msg, "node temperature %.6g degC exceeds t_max_c = %.6g degC at t = %.6g s",
                 T, s->t_max_c, t + h);
        logmsg(inst, fmi2Error, msg);
        return fmi2Error;
    }
    s->T = T;
    s->time = t + h;
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    (void)c; (void)s; (void)value; return fmi2Discard;
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    if (s == fmi2LastSuccessfulTime) { *value = ((Instance *)c)->s.time; return fmi2OK; }
    return fmi2Discard;
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    (void)c; (void)s; (void)value; return fmi2Discard;
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    (void)c; (void)s; (void)value; return fmi2Discard;
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    (void)c; (void)s; (void)value; return fmi2Discard;
}

/* ---- model exchange (not provided: this FMU is co-simulation only) ---- */
fmi2Status fmi2EnterEventMode(fmi2Component c) { (void)c; return fmi2Error; }
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *e) { (void)c; (void)e; return fmi2Error; }
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { (void)c; return fmi2Error; }
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean a, fmi2Boolean *b, fmi2Boolean *d) {
    (void)c; (void)a; (void)b; (void)d; return fmi2Error;
}
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real t) { (void)c; (void)t; return fmi2Error; }
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t n) {
    (void)c; (void)x; (void)n; return fmi2Error;
}
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real d[], size_t n) { (void)c; (void)d; (void)n; return fmi2Error; }
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real e[], size_t n) { (void)c; (void)e; (void)n; return fmi2Error; }
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t n) { (void)c; (void)x; (void)n; return fmi2Error; }
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x[], size_t n) {
    (void)c; (void)x; (void)n; return fmi2Error;
}
