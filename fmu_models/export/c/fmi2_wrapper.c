/* pendulum-cosim: FMI 2.0 Model Exchange + Co-Simulation wrapper around a model core
 * (core_api.h: a plant, an estimator or a signal).
 *
 * Every function checks the instance's state against the FMI 2.0 state machines (sections
 * 3.2.3 and 4.2.4 of the standard) for its interface type; any other call, any NULL argument
 * the standard does not allow and any bad value is answered with fmi2Error and a message
 * through the logger callback (which may be NULL). After an Error the instance is in the
 * tables' error state: fmi2FreeInstance, fmi2Reset, fmi2SetDebugLogging, the FMU-state
 * functions (fmi2SetFMUstate restores a saved state) and, for debugging, the getters are
 * accepted, nothing else. Errors are always logged; loggingOn switches the debug messages. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include "fmi2Functions.h"
#include "core_api.h"
#include "wrapper_modes.h"

typedef struct {
    CoreData d;
    CoreData undo;               /* the data before a changing call (wrapper_common.h) */
    CoreWork wk;
    fmi2Type type;
    Mode mode;
    fmi2CallbackFunctions cb;
    char name[128];
    unsigned cats;
    void **states;
    size_t nstates, cap_states;
    char err[ERRLEN];
} Instance;

static void logmsg(Instance *c, fmi2Status st, const char *cat, const char *fn, const char *text) {
    char msg[2 * ERRLEN + 200];
    size_t j = 0;
    char buf[ERRLEN + 200];
    if (!c || !c->cb.logger || (st < fmi2Warning && !c->cats)) return;
    snprintf(buf, sizeof buf, "%s: %s", fn, text);
    /* the logger treats the message as a printf format and '#' as a reference marker:
     * pass it with no arguments and every '%' and '#' doubled */
    for (size_t i = 0; buf[i] && j + 2 < sizeof msg; i++) {
        if (buf[i] == '%' || buf[i] == '#') msg[j++] = buf[i];
        msg[j++] = buf[i];
    }
    msg[j] = 0;
    c->cb.logger(c->cb.componentEnvironment, c->name, st, cat, msg);
}

static void *mem_alloc(Instance *c, size_t size) {
    void *p = c->cb.allocateMemory(1, size);
    if (p) memset(p, 0, size);
    return p;
}
static void mem_free(Instance *c, void *p) { c->cb.freeMemory(p); }

#define STATUS fmi2Status
#define STATUS_OK fmi2OK
#define STATUS_ERROR fmi2Error
#define IS_CS(c) ((c)->type == fmi2CoSimulation)
#define ERROR_CALLS "fmi2FreeInstance, fmi2Reset, fmi2SetDebugLogging, the FMU-state functions and (values for debugging only) the getters"
#include "wrapper_common.h"

#define ALLOW(fn, cs, me) ALLOW_IN(comp, fn, cs, me)

/* The states of the FMI 2.0 tables (Co-Simulation | Model Exchange); in the error state the
 * getters are allowed with values "usable for debugging only". */
#define CS_RUN B(M_STEP)
#define ME_RUN (B(M_EVENT) | B(M_CONT))
#define GET_CS (B(M_INIT) | CS_RUN | B(M_TERMINATED) | B(M_ERROR))
#define GET_ME (B(M_INIT) | ME_RUN | B(M_TERMINATED) | B(M_ERROR))
#define SET_CS (B(M_INSTANTIATED) | B(M_INIT) | CS_RUN)
#define SET_REAL_ME (B(M_INSTANTIATED) | B(M_INIT) | ME_RUN)
#define SET_DISCRETE_ME (B(M_INSTANTIATED) | B(M_INIT) | B(M_EVENT))   /* not in Continuous-Time Mode */

/* ------------------------------------------------------------------ lifecycle */
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean on, size_t n, const fmi2String cats[]) {
    ALLOW("fmi2SetDebugLogging", ANY, ANY);
    return set_debug_logging(c, "fmi2SetDebugLogging", on != fmi2False, n, cats);
}

/* A failed instantiation: the message through the logger (if any), NULL returned. */
static fmi2Component refuse_instance(Instance *c) {
    c->cb.freeMemory(c);
    return NULL;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String loc,
                              const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean logging) {
    Instance *c;
    (void)loc; (void)visible;
    if (!cb || !cb->allocateMemory || !cb->freeMemory) return NULL;
    c = (Instance *)cb->allocateMemory(1, sizeof(Instance));
    if (!c) {
        if (cb->logger)
            cb->logger(cb->componentEnvironment, name ? name : "", fmi2Error, "logStatusError",
                       "fmi2Instantiate: out of memory");
        return NULL;
    }
    memset(c, 0, sizeof(*c));
    c->cb = *cb;
    c->type = type;
    snprintf(c->name, sizeof c->name, "%s", name ? name : "");
    c->cats = logging ? CAT_ALL_BITS : 0u;
    if (!name || !name[strspn(name, " \t\r\n")]) {
        fail(c, "fmi2Instantiate", "instanceName must be a non-empty string");
        return refuse_instance(c);
    }
    if (!guid || strcmp(guid, MODEL_GUID) != 0) {
        fail(c, "fmi2Instantiate", "GUID %.80s does not match this FMU's %s", guid ? guid : "(null)", MODEL_GUID);
        return refuse_instance(c);
    }
    if (type != fmi2CoSimulation && !(type == fmi2ModelExchange && CORE_HAS_ME)) {
        fail(c, "fmi2Instantiate", "this FMU has no %s interface",
             type == fmi2ModelExchange ? "Model Exchange" : "such");
        return refuse_instance(c);
    }
    core_defaults(&c->d);
    c->mode = M_INSTANTIATED;
    return c;
}

void fmi2FreeInstance(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (!c) return;
    states_free_all(c);
    c->cb.freeMemory(c);
}

fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean tolDef, fmi2Real tol,
                               fmi2Real start, fmi2Boolean stopDef, fmi2Real stop) {
    ALLOW("fmi2SetupExperiment", B(M_INSTANTIATED), B(M_INSTANTIATED));
    if (tolDef && !(tol > 0 && isfinite(tol)))
        return fail(c, "fmi2SetupExperiment", "tolerance %g must be finite and > 0", tol);
    if (!isfinite(start)) return fail(c, "fmi2SetupExperiment", "start time %g is not finite", start);
    if (stopDef && !(stop >= start))
        return fail(c, "fmi2SetupExperiment", "stop time %g is not a time at or after the start time %g", stop, start);
    core_set_time(&c->d, start);
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component comp) {
    ALLOW("fmi2EnterInitializationMode", B(M_INSTANTIATED), B(M_INSTANTIATED));
    c->mode = M_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component comp) {
    ALLOW("fmi2ExitInitializationMode", B(M_INIT), B(M_INIT));
    BEGIN_CHANGE(c);
    if (core_exit_init(&c->wk, &c->d, c->err)) return undo(c, "fmi2ExitInitializationMode");
    c->mode = IS_CS(c) ? M_STEP : M_EVENT;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component comp) {
    ALLOW("fmi2Terminate", CS_RUN, ME_RUN);
    c->mode = M_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component comp) {
    ALLOW("fmi2Reset", ANY, ANY);
    core_defaults(&c->d);
    c->mode = M_INSTANTIATED;
    return fmi2OK;
}

/* ------------------------------------------------------------------ values */
#define VALUES(fn, vr, n, v) ARRAY(fn, vr, n); ARRAY(fn, v, n)

fmi2Status fmi2GetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    ALLOW("fmi2GetReal", GET_CS, GET_ME);
    VALUES("fmi2GetReal", vr, n, v);
    return core(c, "fmi2GetReal", core_get_real(&c->wk, &c->d, vr, n, v, c->err));
}

fmi2Status fmi2SetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    ALLOW("fmi2SetReal", SET_CS, SET_REAL_ME);
    VALUES("fmi2SetReal", vr, n, v);
    BEGIN_CHANGE(c);
    if (core_set_real(&c->d, vr, n, v, SET_WHEN(c), c->err)) return undo(c, "fmi2SetReal");
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component comp, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    long long tmp;
    ALLOW("fmi2GetInteger", GET_CS, GET_ME);
    VALUES("fmi2GetInteger", vr, n, v);
    for (size_t i = 0; i < n; i++) {
        if (core_get_int(&c->d, &vr[i], 1, &tmp, INT_NONE, c->err)) return core(c, "fmi2GetInteger", 1);
        v[i] = (fmi2Integer)tmp;   /* an Integer variable's range is within int (IP_MIN, IP_MAX) */
    }
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component comp, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    ALLOW("fmi2SetInteger", SET_CS, SET_DISCRETE_ME);
    VALUES("fmi2SetInteger", vr, n, v);
    BEGIN_CHANGE(c);
    for (size_t i = 0; i < n; i++) {
        long long tmp = v[i];
        if (core_set_int(&c->d, &vr[i], 1, &tmp, INT_NONE, BEFORE_RUN(c), c->err)) return undo(c, "fmi2SetInteger");
    }
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) {
    ALLOW("fmi2GetBoolean", GET_CS, GET_ME);
    VALUES("fmi2GetBoolean", vr, n, v);
    for (size_t i = 0; i < n; i++) {
        int tmp;
        if (core_get_bool(&c->d, &vr[i], 1, &tmp, c->err)) return core(c, "fmi2GetBoolean", 1);
        v[i] = tmp ? fmi2True : fmi2False;
    }
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) {
    ALLOW("fmi2SetBoolean", SET_CS, SET_DISCRETE_ME);
    VALUES("fmi2SetBoolean", vr, n, v);
    BEGIN_CHANGE(c);
    for (size_t i = 0; i < n; i++) {
        int tmp = v[i] ? 1 : 0;
        if (core_set_bool(&c->d, &vr[i], 1, &tmp, BEFORE_RUN(c), c->err)) return undo(c, "fmi2SetBoolean");
    }
    return fmi2OK;
}

static fmi2Status no_such(Instance *c, const char *fn, const char *type, size_t n, const fmi2ValueReference vr[]) {
    return n ? fail(c, fn, "no %s variable has value reference %u", type, vr[0]) : fmi2OK;
}
fmi2Status fmi2GetString(fmi2Component comp, const fmi2ValueReference vr[], size_t n, fmi2String v[]) {
    ALLOW("fmi2GetString", GET_CS, GET_ME);
    VALUES("fmi2GetString", vr, n, v);
    return no_such(c, "fmi2GetString", "String", n, vr);
}
fmi2Status fmi2SetString(fmi2Component comp, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) {
    ALLOW("fmi2SetString", SET_CS, SET_DISCRETE_ME);
    VALUES("fmi2SetString", vr, n, v);
    return no_such(c, "fmi2SetString", "String", n, vr);
}

/* ------------------------------------------------------------------ FMU state */
fmi2Status fmi2GetFMUstate(fmi2Component comp, fmi2FMUstate *s) {
    ALLOW("fmi2GetFMUstate", ANY, ANY);
    return get_fmu_state(c, "fmi2GetFMUstate", s);
}

fmi2Status fmi2SetFMUstate(fmi2Component comp, fmi2FMUstate s) {
    ALLOW("fmi2SetFMUstate", ANY, ANY);
    return set_fmu_state(c, "fmi2SetFMUstate", s);
}

fmi2Status fmi2FreeFMUstate(fmi2Component comp, fmi2FMUstate *s) {
    ALLOW("fmi2FreeFMUstate", ANY, ANY);
    return free_fmu_state(c, "fmi2FreeFMUstate", s);
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component comp, fmi2FMUstate s, size_t *size) {
    ALLOW("fmi2SerializedFMUstateSize", ANY, ANY);
    return fmu_state_size(c, "fmi2SerializedFMUstateSize", s, size);
}

fmi2Status fmi2SerializeFMUstate(fmi2Component comp, fmi2FMUstate s, fmi2Byte out[], size_t size) {
    ALLOW("fmi2SerializeFMUstate", ANY, ANY);
    return serialize_fmu_state(c, "fmi2SerializeFMUstate", s, out, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component comp, const fmi2Byte in[], size_t size, fmi2FMUstate *s) {
    ALLOW("fmi2DeSerializeFMUstate", ANY, ANY);
    return deserialize_fmu_state(c, "fmi2DeSerializeFMUstate", in, size, s);
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component comp, const fmi2ValueReference unk[], size_t nU,
                                        const fmi2ValueReference kn[], size_t nK,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    ALLOW("fmi2GetDirectionalDerivative", GET_CS, GET_ME);
    if (!CORE_HAS_DERIVATIVES)
        return fail(c, "fmi2GetDirectionalDerivative", "not provided by this FMU (providesDirectionalDerivative = false)");
    ARRAY("fmi2GetDirectionalDerivative", unk, nU);
    ARRAY("fmi2GetDirectionalDerivative", kn, nK);
    ARRAY("fmi2GetDirectionalDerivative", dvKnown, nK);
    ARRAY("fmi2GetDirectionalDerivative", dvUnknown, nU);
    return core(c, "fmi2GetDirectionalDerivative",
                core_directional(&c->wk, &c->d, unk, nU, kn, nK, dvKnown, dvUnknown, c->err));
}

/* ------------------------------------------------------------------ Model Exchange */
/* The number of continuous states passed: the model's. */
#define NSTATES(fn, x, nx) do { ARRAY(fn, x, nx); \
    if ((nx) != (size_t)CORE_NX) return fail(c, fn, "nx = %zu, this model has %d states", (size_t)(nx), CORE_NX); \
    } while (0)

fmi2Status fmi2EnterEventMode(fmi2Component comp) {
    ALLOW("fmi2EnterEventMode", 0, ME_RUN);
    c->mode = M_EVENT;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component comp, fmi2EventInfo *e) {
    ALLOW("fmi2NewDiscreteStates", 0, B(M_EVENT));
    NOT_NULL("fmi2NewDiscreteStates", e);
    memset(e, 0, sizeof(*e));   /* no discrete states, no events, no time events */
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component comp) {
    ALLOW("fmi2EnterContinuousTimeMode", 0, B(M_EVENT));
    c->mode = M_CONT;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component comp, fmi2Boolean noSetPrior,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminate) {
    ALLOW("fmi2CompletedIntegratorStep", 0, B(M_CONT));
    (void)noSetPrior;
    NOT_NULL("fmi2CompletedIntegratorStep", enterEventMode);
    NOT_NULL("fmi2CompletedIntegratorStep", terminate);
    *enterEventMode = fmi2False;
    *terminate = fmi2False;
    return fmi2OK;
}

/* Continuous-Time Mode only: in Event Mode the standard allows it for a pure discrete-time
 * model alone. */
fmi2Status fmi2SetTime(fmi2Component comp, fmi2Real t) {
    ALLOW("fmi2SetTime", 0, B(M_CONT));
    if (!isfinite(t)) return fail(c, "fmi2SetTime", "time %g is not finite", t);
    core_set_time(&c->d, t);
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component comp, const fmi2Real x[], size_t nx) {
    ALLOW("fmi2SetContinuousStates", 0, B(M_CONT));
    NSTATES("fmi2SetContinuousStates", x, nx);
    return core(c, "fmi2SetContinuousStates", core_set_states(&c->d, x, nx, c->err));
}

fmi2Status fmi2GetDerivatives(fmi2Component comp, fmi2Real dx[], size_t nx) {
    ALLOW("fmi2GetDerivatives", 0, GET_ME);
    NSTATES("fmi2GetDerivatives", dx, nx);
    return core(c, "fmi2GetDerivatives", core_derivatives(&c->wk, &c->d, dx, c->err));
}

fmi2Status fmi2GetEventIndicators(fmi2Component comp, fmi2Real ind[], size_t ni) {
    ALLOW("fmi2GetEventIndicators", 0, GET_ME);
    (void)ind;
    return ni ? fail(c, "fmi2GetEventIndicators", "ni = %zu, this model has no event indicators", ni) : fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component comp, fmi2Real x[], size_t nx) {
    ALLOW("fmi2GetContinuousStates", 0, GET_ME);
    NSTATES("fmi2GetContinuousStates", x, nx);
    core_get_states(&c->d, x);
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component comp, fmi2Real nom[], size_t nx) {
    ALLOW("fmi2GetNominalsOfContinuousStates", 0, B(M_INSTANTIATED) | GET_ME);
    NSTATES("fmi2GetNominalsOfContinuousStates", nom, nx);
    for (size_t i = 0; i < nx; i++) nom[i] = 1.0;
    return fmi2OK;
}

/* ------------------------------------------------------------------ Co-Simulation */
fmi2Status fmi2SetRealInputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real v[]) {
    ALLOW("fmi2SetRealInputDerivatives", SET_CS, 0);
    (void)vr; (void)order; (void)v;
    return n ? fail(c, "fmi2SetRealInputDerivatives", "inputs are held constant over a step (canInterpolateInputs = false)") : fmi2OK;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real v[]) {
    ALLOW("fmi2GetRealOutputDerivatives", CS_RUN | B(M_TERMINATED) | B(M_ERROR), 0);
    (void)vr; (void)order; (void)v;
    return n ? fail(c, "fmi2GetRealOutputDerivatives", "output derivatives are not provided (maxOutputDerivativeOrder = 0)") : fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    ALLOW("fmi2DoStep", CS_RUN, 0);
    (void)noSetPrior;
    BEGIN_CHANGE(c);
    if (core_do_step(&c->wk, &c->d, t, h, c->err)) return undo(c, "fmi2DoStep");
    return fmi2OK;
}

/* doStep never returns fmi2Pending: there is no step in progress to cancel or ask about. */
fmi2Status fmi2CancelStep(fmi2Component comp) {
    ALLOW("fmi2CancelStep", ANY, 0);
    return fail(c, "fmi2CancelStep", "no step in progress in %s: doStep never returns fmi2Pending", mode_name(c->mode));
}

#define NO_STATUS(fn, T) fmi2Status fn(fmi2Component comp, const fmi2StatusKind s, T *v) { \
    ALLOW(#fn, CS_RUN | B(M_TERMINATED), 0); (void)s; (void)v; \
    return fail(c, #fn, "no status to report: doStep never returns fmi2Pending or fmi2Discard"); }
NO_STATUS(fmi2GetStatus, fmi2Status)
NO_STATUS(fmi2GetRealStatus, fmi2Real)
NO_STATUS(fmi2GetIntegerStatus, fmi2Integer)
NO_STATUS(fmi2GetBooleanStatus, fmi2Boolean)
NO_STATUS(fmi2GetStringStatus, fmi2String)
