/* pendulum-cosim: FMI 2.0 Model Exchange + Co-Simulation wrapper around plant_core.
 * Every error is answered with fmi2Error and a message through the logger callback. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include "fmi2Functions.h"
#include "plant_core.h"

typedef enum { M_INSTANTIATED, M_INIT, M_STEP, M_EVENT, M_CONT, M_TERMINATED, M_ERROR } Mode;

typedef struct {
    PlantData d;
    PlantWork wk;
    fmi2Type type;
    Mode mode;
    fmi2CallbackFunctions cb;
    char name[128];
    int logging;
} Instance;

#define STATE_MAGIC 0x50435354u /* "PCST" */
typedef struct { unsigned magic; unsigned size; PlantData d; } SavedState;

static void logmsg(Instance *c, fmi2Status st, const char *cat, const char *fmt, ...) {
    char buf[512];
    va_list ap;
    if (!c || !c->cb.logger) return;
    if (st < fmi2Warning && !c->logging) return;
    char msg[1100];
    size_t j = 0;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    /* the logger treats the message as a printf format (and '#' as a reference marker):
     * pass it with no arguments and every '%' and '#' escaped */
    for (size_t i = 0; buf[i] && j + 2 < sizeof msg; i++) {
        if (buf[i] == '%' || buf[i] == '#') msg[j++] = buf[i];
        msg[j++] = buf[i];
    }
    msg[j] = 0;
    c->cb.logger(c->cb.componentEnvironment, c->name, st, cat, msg);
}

static fmi2Status fail(Instance *c, const char *fn, const char *fmt, ...) {
    char buf[400];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    logmsg(c, fmi2Error, "logStatusError", "%s: %s", fn, buf);
    return fmi2Error;
}

static const char *mode_name(Mode m) {
    static const char *n[] = {"instantiated", "initialization mode", "step mode", "event mode",
                              "continuous-time mode", "terminated", "error"};
    return n[m];
}

/* Allowed-mode check; mask bit i for Mode i. */
#define ALLOW(c, fn, mask) do { if (!(c)) return fmi2Error; \
    if (!((1u << (c)->mode) & (mask))) \
        return fail((c), (fn), "not allowed in %s", mode_name((c)->mode)); } while (0)
#define B(m) (1u << (m))
#define ANY_LIVE (B(M_INSTANTIATED) | B(M_INIT) | B(M_STEP) | B(M_EVENT) | B(M_CONT) | B(M_TERMINATED))
#define RUNNING (B(M_STEP) | B(M_EVENT) | B(M_CONT))

/* ------------------------------------------------------------------ lifecycle */
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean on, size_t n, const fmi2String cats[]) {
    Instance *c = (Instance *)comp;
    (void)n; (void)cats;
    if (!c) return fmi2Error;
    c->logging = on ? 1 : 0;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String loc,
                              const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean logging) {
    Instance *c;
    (void)loc; (void)visible;
    if (!cb || !cb->allocateMemory || !cb->freeMemory) return NULL;
    c = (Instance *)cb->allocateMemory(1, sizeof(Instance));
    if (!c) return NULL;
    memset(c, 0, sizeof(*c));
    c->cb = *cb;
    snprintf(c->name, sizeof c->name, "%s", name ? name : "");
    c->logging = logging ? 1 : 0;
    if (!guid || strcmp(guid, MODEL_GUID) != 0) {
        fail(c, "fmi2Instantiate", "GUID %s does not match this FMU's %s", guid ? guid : "(null)", MODEL_GUID);
        cb->freeMemory(c);
        return NULL;
    }
    if (type != fmi2ModelExchange && type != fmi2CoSimulation) {
        fail(c, "fmi2Instantiate", "unknown fmuType %d", (int)type);
        cb->freeMemory(c);
        return NULL;
    }
    c->type = type;
    plant_defaults(&c->d);
    c->mode = M_INSTANTIATED;
    return c;
}

void fmi2FreeInstance(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (c) c->cb.freeMemory(c);
}

fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean tolDef, fmi2Real tol,
                               fmi2Real start, fmi2Boolean stopDef, fmi2Real stop) {
    Instance *c = (Instance *)comp;
    (void)tolDef; (void)tol;
    ALLOW(c, "fmi2SetupExperiment", B(M_INSTANTIATED));
    if (!isfinite(start)) return fail(c, "fmi2SetupExperiment", "start time must be finite");
    if (stopDef && !(stop >= start)) return fail(c, "fmi2SetupExperiment", "stop time %g < start time %g", stop, start);
    c->d.time = start;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    ALLOW(c, "fmi2EnterInitializationMode", B(M_INSTANTIATED));
    c->mode = M_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    ALLOW(c, "fmi2ExitInitializationMode", B(M_INIT));
    for (int k = 0; k < NP; k++) {
        const char *why = plant_check_param(k, c->d.p[k]);
        if (why) { c->mode = M_ERROR; return fail(c, "fmi2ExitInitializationMode", "parameter %s = %g %s", REAL_NAMES[VR_P + k], c->d.p[k], why); }
    }
    for (int i = 0; i < NX; i++)
        if (!isfinite(c->d.x[i])) { c->mode = M_ERROR; return fail(c, "fmi2ExitInitializationMode", "start value of %s is not finite", REAL_NAMES[VR_X + i]); }
    c->mode = c->type == fmi2CoSimulation ? M_STEP : M_EVENT;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    ALLOW(c, "fmi2Terminate", RUNNING | B(M_ERROR));
    c->mode = M_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (!c) return fmi2Error;
    plant_defaults(&c->d);
    c->mode = M_INSTANTIATED;
    return fmi2OK;
}

/* ------------------------------------------------------------------ values */
/* Real value of a variable that is stored (not calculated); *ok = 0 if vr is not one. */
static double stored_real(Instance *c, fmi2ValueReference vr, int *ok) {
    *ok = 1;
    if (vr < VR_P + NP) return c->d.p[vr - VR_P];
    if (vr == VR_STEP) return c->d.step_size;
    if (vr >= VR_X && vr < VR_X + NX) return c->d.x[vr - VR_X];
    if (vr >= VR_U && vr < VR_U + NU) return c->d.u[vr - VR_U];
    if (vr >= VR_W && vr < VR_W + NX) return c->d.w[vr - VR_W];
    *ok = 0;
    return NAN;
}

fmi2Status fmi2GetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    Instance *c = (Instance *)comp;
    double xdot[NX], y[NY];
    int have_xdot = 0, have_y = 0, ok;
    ALLOW(c, "fmi2GetReal", ANY_LIVE);
    for (size_t i = 0; i < n; i++) {
        fmi2ValueReference r = vr[i];
        if (r >= VR_DX && r < VR_DX + NX) {
            if (!have_xdot) { plant_f(&c->wk, &c->d, c->d.x, xdot); have_xdot = 1; }
            v[i] = xdot[r - VR_DX];
        } else if (r >= VR_Y && r < VR_Y + NY) {
            if (!have_y) { plant_h(&c->wk, &c->d, y); have_y = 1; }
            v[i] = y[r - VR_Y];
        } else {
            v[i] = stored_real(c, r, &ok);
            if (!ok) return fail(c, "fmi2GetReal", "no Real variable has value reference %u", r);
        }
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    Instance *c = (Instance *)comp;
    const unsigned before_run = B(M_INSTANTIATED) | B(M_INIT);
    ALLOW(c, "fmi2SetReal", ANY_LIVE & ~B(M_TERMINATED));
    for (size_t i = 0; i < n; i++) {
        fmi2ValueReference r = vr[i];
        if (r >= N_REAL) return fail(c, "fmi2SetReal", "no Real variable has value reference %u", r);
        if (!isfinite(v[i])) return fail(c, "fmi2SetReal", "%s: value %g is not finite", REAL_NAMES[r], v[i]);
        if (r < VR_P + NP) {
            const char *why = plant_check_param(r - VR_P, v[i]);
            if (!((1u << c->mode) & before_run))
                return fail(c, "fmi2SetReal", "parameter %s is fixed: set it before fmi2ExitInitializationMode", REAL_NAMES[r]);
            if (why) return fail(c, "fmi2SetReal", "parameter %s = %g %s", REAL_NAMES[r], v[i], why);
            c->d.p[r - VR_P] = v[i];
        } else if (r == VR_STEP) {
            if (!((1u << c->mode) & before_run))
                return fail(c, "fmi2SetReal", "step_size is fixed: set it before fmi2ExitInitializationMode");
            if (!(v[i] > 0)) return fail(c, "fmi2SetReal", "step_size = %g must be > 0", v[i]);
            c->d.step_size = v[i];
        } else if (r >= VR_X && r < VR_X + NX) {
            if (!((1u << c->mode) & before_run))
                return fail(c, "fmi2SetReal", "start value of state %s can only be set before fmi2ExitInitializationMode (use fmi2SetFMUstate or fmi2SetContinuousStates)", REAL_NAMES[r]);
            c->d.x[r - VR_X] = v[i];
        } else if (r >= VR_U && r < VR_U + NU) {
            c->d.u[r - VR_U] = v[i];
        } else if (r >= VR_W && r < VR_W + NX) {
            c->d.w[r - VR_W] = v[i];
        } else {
            return fail(c, "fmi2SetReal", "%s is calculated and cannot be set", REAL_NAMES[r]);
        }
    }
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component comp, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    Instance *c = (Instance *)comp;
    ALLOW(c, "fmi2GetInteger", ANY_LIVE);
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == VR_INTEGRATOR) v[i] = c->d.integrator;
        else if (vr[i] == VR_SUBSTEPS) v[i] = c->d.substeps;
        else return fail(c, "fmi2GetInteger", "no Integer variable has value reference %u", vr[i]);
    }
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component comp, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    Instance *c = (Instance *)comp;
    ALLOW(c, "fmi2SetInteger", B(M_INSTANTIATED) | B(M_INIT));
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == VR_INTEGRATOR) {
            if (v[i] != INTEGRATOR_EULER && v[i] != INTEGRATOR_RK4)
                return fail(c, "fmi2SetInteger", "integrator = %d: valid values are 1 (euler) and 2 (rk4)", (int)v[i]);
            c->d.integrator = v[i];
        } else if (vr[i] == VR_SUBSTEPS) {
            if (v[i] < 1) return fail(c, "fmi2SetInteger", "substeps = %d must be >= 1", (int)v[i]);
            c->d.substeps = v[i];
        } else return fail(c, "fmi2SetInteger", "no Integer variable has value reference %u", vr[i]);
    }
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) {
    Instance *c = (Instance *)comp;
    (void)v;
    ALLOW(c, "fmi2GetBoolean", ANY_LIVE);
    return n ? fail(c, "fmi2GetBoolean", "no Boolean variable has value reference %u", vr[0]) : fmi2OK;
}
fmi2Status fmi2SetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) {
    Instance *c = (Instance *)comp;
    (void)v;
    ALLOW(c, "fmi2SetBoolean", ANY_LIVE);
    return n ? fail(c, "fmi2SetBoolean", "no Boolean variable has value reference %u", vr[0]) : fmi2OK;
}
fmi2Status fmi2GetString(fmi2Component comp, const fmi2ValueReference vr[], size_t n, fmi2String v[]) {
    Instance *c = (Instance *)comp;
    (void)v;
    ALLOW(c, "fmi2GetString", ANY_LIVE);
    return n ? fail(c, "fmi2GetString", "no String variable has value reference %u", vr[0]) : fmi2OK;
}
fmi2Status fmi2SetString(fmi2Component comp, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) {
    Instance *c = (Instance *)comp;
    (void)v;
    ALLOW(c, "fmi2SetString", ANY_LIVE);
    return n ? fail(c, "fmi2SetString", "no String variable has value reference %u", vr[0]) : fmi2OK;
}

/* ------------------------------------------------------------------ FMU state */
fmi2Status fmi2GetFMUstate(fmi2Component comp, fmi2FMUstate *s) {
    Instance *c = (Instance *)comp;
    ALLOW(c, "fmi2GetFMUstate", ANY_LIVE);
    if (!s) return fail(c, "fmi2GetFMUstate", "FMUstate pointer is NULL");
    if (!*s) {
        *s = c->cb.allocateMemory(1, sizeof(SavedState));
        if (!*s) return fail(c, "fmi2GetFMUstate", "out of memory");
    }
    ((SavedState *)*s)->magic = STATE_MAGIC;
    ((SavedState *)*s)->size = sizeof(SavedState);
    ((SavedState *)*s)->d = c->d;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component comp, fmi2FMUstate s) {
    Instance *c = (Instance *)comp;
    const SavedState *st = (const SavedState *)s;
    ALLOW(c, "fmi2SetFMUstate", ANY_LIVE);
    if (!st || st->magic != STATE_MAGIC || st->size != sizeof(SavedState))
        return fail(c, "fmi2SetFMUstate", "not an FMU state of this FMU");
    c->d = st->d;
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component comp, fmi2FMUstate *s) {
    Instance *c = (Instance *)comp;
    if (!c) return fmi2Error;
    if (s && *s) { c->cb.freeMemory(*s); *s = NULL; }
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component comp, fmi2FMUstate s, size_t *size) {
    Instance *c = (Instance *)comp;
    (void)s;
    ALLOW(c, "fmi2SerializedFMUstateSize", ANY_LIVE);
    *size = sizeof(SavedState);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component comp, fmi2FMUstate s, fmi2Byte out[], size_t size) {
    Instance *c = (Instance *)comp;
    ALLOW(c, "fmi2SerializeFMUstate", ANY_LIVE);
    if (!s) return fail(c, "fmi2SerializeFMUstate", "FMUstate is NULL");
    if (size < sizeof(SavedState)) return fail(c, "fmi2SerializeFMUstate", "buffer of %zu bytes, need %zu", size, sizeof(SavedState));
    memcpy(out, s, sizeof(SavedState));
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component comp, const fmi2Byte in[], size_t size, fmi2FMUstate *s) {
    Instance *c = (Instance *)comp;
    SavedState tmp;
    ALLOW(c, "fmi2DeSerializeFMUstate", ANY_LIVE);
    if (size != sizeof(SavedState)) return fail(c, "fmi2DeSerializeFMUstate", "%zu bytes, expected %zu", size, sizeof(SavedState));
    memcpy(&tmp, in, sizeof tmp);
    if (tmp.magic != STATE_MAGIC || tmp.size != sizeof(SavedState))
        return fail(c, "fmi2DeSerializeFMUstate", "bytes are not a serialised state of this FMU");
    if (!*s) {
        *s = c->cb.allocateMemory(1, sizeof(SavedState));
        if (!*s) return fail(c, "fmi2DeSerializeFMUstate", "out of memory");
    }
    memcpy(*s, &tmp, sizeof tmp);
    return fmi2OK;
}

/* ------------------------------------------------------------------ derivatives */
fmi2Status fmi2GetDirectionalDerivative(fmi2Component comp, const fmi2ValueReference unk[], size_t nU,
                                        const fmi2ValueReference kn[], size_t nK,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    Instance *c = (Instance *)comp;
    double A[NX * NX], Bm[NX * (NU > 0 ? NU : 1)], H[NY * NX];
    ALLOW(c, "fmi2GetDirectionalDerivative", B(M_INIT) | RUNNING);
    for (size_t k = 0; k < nK; k++) {
        fmi2ValueReference r = kn[k];
        if (!((r >= VR_X && r < VR_X + NX) || (r >= VR_U && r < VR_U + NU) || (r >= VR_W && r < VR_W + NX)))
            return fail(c, "fmi2GetDirectionalDerivative", "value reference %u is not a state or an input", r);
    }
    plant_jacobians(&c->wk, &c->d, A, Bm, H);
    for (size_t i = 0; i < nU; i++) {
        fmi2ValueReference r = unk[i];
        double s = 0;
        for (size_t k = 0; k < nK; k++) {
            fmi2ValueReference q = kn[k];
            double dz = 0;
            if (r >= VR_DX && r < VR_DX + NX) {
                if (q >= VR_X && q < VR_X + NX) dz = A[(r - VR_DX) + NX * (q - VR_X)];
                else if (q >= VR_U && q < VR_U + NU) dz = Bm[(r - VR_DX) + NX * (q - VR_U)];
            } else if (r >= VR_Y && r < VR_Y + NY) {
                if (q >= VR_X && q < VR_X + NX) dz = H[(r - VR_Y) + NY * (q - VR_X)];
            } else if (r >= VR_X && r < VR_X + NX) {
                dz = (q == r) ? 1.0 : 0.0;
            } else {
                return fail(c, "fmi2GetDirectionalDerivative", "value reference %u is not a derivative or an output", r);
            }
            s += dz * dvKnown[k];
        }
        dvUnknown[i] = s;
    }
    return fmi2OK;
}

/* ------------------------------------------------------------------ Model Exchange */
fmi2Status fmi2EnterEventMode(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    ALLOW(c, "fmi2EnterEventMode", B(M_EVENT) | B(M_CONT));
    c->mode = M_EVENT;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component comp, fmi2EventInfo *e) {
    Instance *c = (Instance *)comp;
    ALLOW(c, "fmi2NewDiscreteStates", B(M_EVENT));
    e->newDiscreteStatesNeeded = fmi2False;
    e->terminateSimulation = fmi2False;
    e->nominalsOfContinuousStatesChanged = fmi2False;
    e->valuesOfContinuousStatesChanged = fmi2False;
    e->nextEventTimeDefined = fmi2False;
    e->nextEventTime = 0;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    ALLOW(c, "fmi2EnterContinuousTimeMode", B(M_EVENT));
    c->mode = M_CONT;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component comp, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminate) {
    Instance *c = (Instance *)comp;
    (void)noSetFMUStatePriorToCurrentPoint;
    ALLOW(c, "fmi2CompletedIntegratorStep", B(M_CONT));
    *enterEventMode = fmi2False;
    *terminate = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component comp, fmi2Real t) {
    Instance *c = (Instance *)comp;
    ALLOW(c, "fmi2SetTime", B(M_EVENT) | B(M_CONT));
    if (!isfinite(t)) return fail(c, "fmi2SetTime", "time %g is not finite", t);
    c->d.time = t;
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component comp, const fmi2Real x[], size_t nx) {
    Instance *c = (Instance *)comp;
    ALLOW(c, "fmi2SetContinuousStates", B(M_CONT));
    if (nx != NX) return fail(c, "fmi2SetContinuousStates", "nx = %zu, this model has %d states", nx, NX);
    for (size_t i = 0; i < nx; i++)
        if (!isfinite(x[i])) return fail(c, "fmi2SetContinuousStates", "state %s = %g is not finite", REAL_NAMES[VR_X + i], x[i]);
    memcpy(c->d.x, x, sizeof(double) * NX);
    return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component comp, fmi2Real dx[], size_t nx) {
    Instance *c = (Instance *)comp;
    ALLOW(c, "fmi2GetDerivatives", B(M_INIT) | B(M_EVENT) | B(M_CONT) | B(M_TERMINATED));
    if (nx != NX) return fail(c, "fmi2GetDerivatives", "nx = %zu, this model has %d states", nx, NX);
    plant_f(&c->wk, &c->d, c->d.x, dx);
    for (size_t i = 0; i < nx; i++)
        if (!isfinite(dx[i])) return fail(c, "fmi2GetDerivatives", "der(%s) is not finite", REAL_NAMES[VR_X + i]);
    return fmi2OK;
}

fmi2Status fmi2GetEventIndicators(fmi2Component comp, fmi2Real ind[], size_t ni) {
    Instance *c = (Instance *)comp;
    (void)ind;
    ALLOW(c, "fmi2GetEventIndicators", ANY_LIVE);
    return ni ? fail(c, "fmi2GetEventIndicators", "this model has no event indicators") : fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component comp, fmi2Real x[], size_t nx) {
    Instance *c = (Instance *)comp;
    ALLOW(c, "fmi2GetContinuousStates", ANY_LIVE);
    if (nx != NX) return fail(c, "fmi2GetContinuousStates", "nx = %zu, this model has %d states", nx, NX);
    memcpy(x, c->d.x, sizeof(double) * NX);
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component comp, fmi2Real nom[], size_t nx) {
    Instance *c = (Instance *)comp;
    ALLOW(c, "fmi2GetNominalsOfContinuousStates", ANY_LIVE);
    if (nx != NX) return fail(c, "fmi2GetNominalsOfContinuousStates", "nx = %zu, this model has %d states", nx, NX);
    for (size_t i = 0; i < nx; i++) nom[i] = 1.0;
    return fmi2OK;
}

/* ------------------------------------------------------------------ Co-Simulation */
fmi2Status fmi2SetRealInputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real v[]) {
    Instance *c = (Instance *)comp;
    (void)vr; (void)order; (void)v;
    ALLOW(c, "fmi2SetRealInputDerivatives", ANY_LIVE);
    return n ? fail(c, "fmi2SetRealInputDerivatives", "inputs are held constant over a step (canInterpolateInputs=false)") : fmi2OK;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real v[]) {
    Instance *c = (Instance *)comp;
    (void)vr; (void)order; (void)v;
    ALLOW(c, "fmi2GetRealOutputDerivatives", ANY_LIVE);
    return n ? fail(c, "fmi2GetRealOutputDerivatives", "output derivatives are not provided (maxOutputDerivativeOrder=0)") : fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    Instance *c = (Instance *)comp;
    (void)noSetPrior;
    ALLOW(c, "fmi2DoStep", B(M_STEP));
    if (c->type != fmi2CoSimulation) return fail(c, "fmi2DoStep", "instance was not instantiated for Co-Simulation");
    if (!(h > 0) || !isfinite(h)) return fail(c, "fmi2DoStep", "communication step size %g must be > 0", h);
    if (fabs(t - c->d.time) > 1e-9 * fmax(1.0, fabs(t)))
        return fail(c, "fmi2DoStep", "currentCommunicationPoint %.17g differs from the FMU time %.17g", t, c->d.time);
    c->d.time = t;
    if (plant_advance(&c->wk, &c->d, h))
        return fail(c, "fmi2DoStep", "the state became non-finite in the step from t = %g s to %g s; state kept at t = %g s", t, t + h, t);
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    ALLOW(c, "fmi2CancelStep", B(M_STEP));
    return fail(c, "fmi2CancelStep", "doStep is synchronous: nothing to cancel");
}

static fmi2Status no_status(Instance *c, const char *fn) {
    ALLOW(c, fn, ANY_LIVE);
    return fail(c, fn, "doStep is synchronous: there is no pending status");
}
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) { (void)s; (void)v; return no_status((Instance *)c, "fmi2GetStatus"); }
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) { (void)s; (void)v; return no_status((Instance *)c, "fmi2GetRealStatus"); }
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) { (void)s; (void)v; return no_status((Instance *)c, "fmi2GetIntegerStatus"); }
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) { (void)s; (void)v; return no_status((Instance *)c, "fmi2GetBooleanStatus"); }
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) { (void)s; (void)v; return no_status((Instance *)c, "fmi2GetStringStatus"); }
