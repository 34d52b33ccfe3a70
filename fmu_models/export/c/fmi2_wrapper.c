/* pendulum-cosim: FMI 2.0 Model Exchange + Co-Simulation wrapper around a model core
 * (core_api.h: a plant, an estimator or a signal).
 *
 * Every function checks the instance's state against the FMI 2.0 state machines (sections
 * 3.2.3 and 4.2.4 of the standard) for its interface type; any other call, any NULL argument
 * the standard does not allow and any bad value is answered with fmi2Error and a message
 * through the logger callback (which may be NULL). After an Error the instance is in the
 * tables' error state: fmi2FreeInstance, fmi2Reset, fmi2SetDebugLogging, the FMU-state
 * functions but fmi2GetFMUstate (fmi2SetFMUstate restores a state saved before the error, with
 * that state's rules) and, for debugging, the getters are accepted, nothing else. Errors are always logged; loggingOn switches the debug messages.
 *
 * This file is the FMI 2.0 API over the parts both wrappers share: wrapper_common.h (the
 * state machine, errors, FMU states) and wrapper_functions.h (the calls and functions written
 * once for both versions). */
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

#define FMI_VERSION 2
#define IS_CS(c) ((c)->type == fmi2CoSimulation)
#include "wrapper_common.h"
#define HANDLE fmi2Component
#define REAL fmi2Real
#include "wrapper_functions.h"

/* The Co-Simulation states of the FMI 2.0 tables besides wrapper_modes.h's. */
#define GET_CS (B(M_INIT) | CS_RUN | B(M_TERMINATED) | B(M_ERROR))
#define SET_CS (B(M_INSTANTIATED) | B(M_INIT) | CS_RUN)

/* ------------------------------------------------------------------ lifecycle */
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

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

fmi2Status fmi2SetupExperiment(fmi2Component inst, fmi2Boolean tolDef, fmi2Real tol,
                               fmi2Real start, fmi2Boolean stopDef, fmi2Real stop) {
    ALLOW("fmi2SetupExperiment", B(M_INSTANTIATED), B(M_INSTANTIATED));
    return start_experiment(c, "fmi2SetupExperiment", tolDef, tol, start, stopDef, stop);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component inst) {
    ALLOW("fmi2EnterInitializationMode", B(M_INSTANTIATED), B(M_INSTANTIATED));
    c->mode = M_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component inst) {
    ALLOW("fmi2ExitInitializationMode", B(M_INIT), B(M_INIT));
    return exit_initialization(c, "fmi2ExitInitializationMode", IS_CS(c) ? M_STEP : M_EVENT);
}

fmi2Status fmi2Terminate(fmi2Component inst) {
    ALLOW("fmi2Terminate", CS_RUN, ME_RUN);
    c->mode = M_TERMINATED;
    return fmi2OK;
}

/* ------------------------------------------------------------------ values */
#define VALUES(fn, vr, n, v) ARRAY(fn, vr, n); ARRAY(fn, v, n)
/* The getter GET and setter SET of the type T over the shared calls get and set. */
#define VALUE_FUNCTIONS(T, GET, SET, me_mask, get, set)                                             \
    fmi2Status GET(fmi2Component inst, const fmi2ValueReference vr[], size_t n, T v[]) {            \
        ALLOW(#GET, GET_CS, GET_ME);                                                                \
        VALUES(#GET, vr, n, v);                                                                     \
        return get(c, #GET, vr, n, v);                                                              \
    }                                                                                               \
    fmi2Status SET(fmi2Component inst, const fmi2ValueReference vr[], size_t n, const T v[]) {      \
        ALLOW(#SET, SET_CS, me_mask);                                                               \
        VALUES(#SET, vr, n, v);                                                                     \
        return set(c, #SET, vr, n, v);                                                              \
    }

INT_CALLS(fmi2Integer, INT_NONE)   /* an Integer variable's range is within int (IP_MIN, IP_MAX) */
VALUE_FUNCTIONS(fmi2Real, fmi2GetReal, fmi2SetReal, SET_REAL_ME, get_reals, set_reals)
VALUE_FUNCTIONS(fmi2Integer, fmi2GetInteger, fmi2SetInteger, SET_DISCRETE_ME, get_fmi2Integer, set_fmi2Integer)
VALUE_FUNCTIONS(fmi2Boolean, fmi2GetBoolean, fmi2SetBoolean, SET_DISCRETE_ME, get_booleans, set_booleans)

static fmi2Status no_such(Instance *c, const char *fn, const char *type, size_t n, const fmi2ValueReference vr[]) {
    return n ? fail(c, fn, "no %s variable has value reference %u", type, vr[0]) : fmi2OK;
}
fmi2Status fmi2GetString(fmi2Component inst, const fmi2ValueReference vr[], size_t n, fmi2String v[]) {
    ALLOW("fmi2GetString", GET_CS, GET_ME);
    VALUES("fmi2GetString", vr, n, v);
    return no_such(c, "fmi2GetString", "String", n, vr);
}
fmi2Status fmi2SetString(fmi2Component inst, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) {
    ALLOW("fmi2SetString", SET_CS, SET_DISCRETE_ME);
    VALUES("fmi2SetString", vr, n, v);
    return no_such(c, "fmi2SetString", "String", n, vr);
}

/* ------------------------------------------------------------------ FMU state */
FMU_STATE_FUNCTIONS(fmi2FMUstate, fmi2GetFMUstate, fmi2SetFMUstate, fmi2FreeFMUstate, fmi2SerializedFMUstateSize,
                    fmi2SerializeFMUstate, fmi2DeSerializeFMUstate)

fmi2Status fmi2GetDirectionalDerivative(fmi2Component inst, const fmi2ValueReference unk[], size_t nU,
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
fmi2Status fmi2EnterEventMode(fmi2Component inst) {
    ALLOW("fmi2EnterEventMode", 0, ME_RUN);
    c->mode = M_EVENT;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component inst, fmi2EventInfo *e) {
    ALLOW("fmi2NewDiscreteStates", 0, B(M_EVENT));
    NOT_NULL("fmi2NewDiscreteStates", e);
    memset(e, 0, sizeof(*e));   /* no discrete states, no events, no time events */
    return fmi2OK;
}

COMPLETED_INTEGRATOR_STEP(enterEventMode, terminate)
GET_DERIVATIVES(fmi2GetDerivatives)

fmi2Status fmi2GetEventIndicators(fmi2Component inst, fmi2Real ind[], size_t ni) {
    ALLOW("fmi2GetEventIndicators", 0, GET_ME);
    (void)ind;
    return ni ? fail(c, "fmi2GetEventIndicators", "ni = %zu, this model has no event indicators", ni) : fmi2OK;
}

GET_NOMINALS(B(M_INSTANTIATED) | GET_ME)

/* ------------------------------------------------------------------ Co-Simulation */
fmi2Status fmi2SetRealInputDerivatives(fmi2Component inst, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real v[]) {
    ALLOW("fmi2SetRealInputDerivatives", SET_CS, 0);
    (void)vr; (void)order; (void)v;
    return n ? fail(c, "fmi2SetRealInputDerivatives", "inputs are held constant over a step (canInterpolateInputs = false)") : fmi2OK;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component inst, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real v[]) {
    ALLOW("fmi2GetRealOutputDerivatives", CS_RUN | B(M_TERMINATED) | B(M_ERROR), 0);
    (void)vr; (void)order; (void)v;
    return n ? fail(c, "fmi2GetRealOutputDerivatives", "output derivatives are not provided (maxOutputDerivativeOrder = 0)") : fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component inst, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    ALLOW("fmi2DoStep", CS_RUN, 0);
    (void)noSetPrior;
    return do_step(c, "fmi2DoStep", t, h);
}

/* doStep never returns fmi2Pending: there is no step in progress to cancel or ask about. */
fmi2Status fmi2CancelStep(fmi2Component inst) {
    ALLOW("fmi2CancelStep", ANY, 0);
    return fail(c, "fmi2CancelStep", "no step in progress in %s: doStep never returns fmi2Pending", mode_name(c->mode));
}

#define NO_STATUS(fn, T) fmi2Status fn(fmi2Component inst, const fmi2StatusKind s, T *v) { \
    ALLOW(#fn, CS_RUN | B(M_TERMINATED), 0); (void)s; (void)v; \
    return fail(c, #fn, "no status to report: doStep never returns fmi2Pending or fmi2Discard"); }
NO_STATUS(fmi2GetStatus, fmi2Status)
NO_STATUS(fmi2GetRealStatus, fmi2Real)
NO_STATUS(fmi2GetIntegerStatus, fmi2Integer)
NO_STATUS(fmi2GetBooleanStatus, fmi2Boolean)
NO_STATUS(fmi2GetStringStatus, fmi2String)
