/* pendulum-cosim: FMI 3.0 Model Exchange + Co-Simulation wrapper around a model core
 * (core_api.h: a plant, an estimator or a signal). Every FMI 3.0 function is exported
 * (importers such as fmpy load them all by name).
 *
 * Every function checks the instance's state against the FMI 3.0 state machine (the allowed
 * function calls of each state, sections 2.3, 3.2 and 4.2 of the standard) for its interface
 * type; any other call, any NULL argument the standard does not allow, any bad value and any
 * function this FMU does not support is answered with fmi3Error. After an Error the simulation
 * cannot go on: fmi3FreeInstance, fmi3Reset, fmi3SetDebugLogging, the FMU-state functions but
 * fmi3GetFMUState (fmi3SetFMUState restores a state saved before the error, with that state's
 * rules) and, for debugging, the getters are accepted, nothing else. The log callback is called only for the enabled categories: none when the
 * instance was created with loggingOn = false (errors included), as the standard says.
 *
 * Unclocked form: the Co-Simulation interface has no Event Mode (hasEventMode = false):
 * eventModeUsed = true is refused; there is no Scheduled Execution interface.
 *
 * Clocked form (model_config.h defines CLOCK_VR; core_api.h): the input clock `sample`
 * (intervalVariability constant, the core's period, first activation at the start time)
 * clocks the core's inputs and outputs, which are set and got only while it is active:
 *   - Co-Simulation with Event Mode (eventModeUsed = true required): after
 *     fmi3ExitInitializationMode the instance is in Event Mode; at each activation time the
 *     importer enters Event Mode, activates the clock with fmi3SetClock (only when it is due),
 *     sets the clocked inputs, gets the clocked outputs and ends the super-dense instant with
 *     fmi3UpdateDiscreteStates (which commits the activation). fmi3DoStep only advances time
 *     and refuses to step past a due activation or from one not made; fmi3EnterStepMode is
 *     refused while the clock is active.
 *   - Scheduled Execution: after fmi3ExitInitializationMode the instance is in Clock
 *     Activation Mode; inputs are set before fmi3ActivateModelPartition(sample, t), which runs
 *     the activation due at t, and the clocked variables are got after it (not after a set
 *     without an activation in between, as the standard says).
 * The clock cannot be deactivated, has no fraction form, and its interval and shift cannot be
 * set; fmi3GetIntervalDecimal and fmi3GetShiftDecimal answer the declared ones.
 *
 * This file is the FMI 3.0 API over the parts both wrappers share: wrapper_common.h (the
 * state machine, errors, FMU states) and wrapper_functions.h (the calls and functions written
 * once for both versions). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi3Functions.h"
#include "core_api.h"
#include "wrapper_modes.h"

typedef enum { ME, CS, SE } Kind;   /* = KIND_CODE */

typedef struct {
    CoreData d;
    CoreData undo;               /* the data before a changing call (wrapper_common.h) */
    CoreWork wk;
    Kind kind;
    Mode mode;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
    unsigned cats;
    void **states;
    size_t nstates, cap_states;
    char err[ERRLEN];
} Instance;

static void logmsg(Instance *c, fmi3Status st, const char *cat, const char *fn, const char *text) {
    char buf[ERRLEN + 200], msg[2 * ERRLEN + 400];
    size_t j = 0;
    (void)st;
    if (!c || !c->log || !(c->cats & CAT_ERROR)) return;
    snprintf(buf, sizeof buf, "%s: %s", fn, text);
    /* '#' marks a value reference in FMI 3.0 messages: a literal one is written twice */
    for (size_t i = 0; buf[i] && j + 2 < sizeof msg; i++) {
        if (buf[i] == '#') msg[j++] = '#';
        msg[j++] = buf[i];
    }
    msg[j] = 0;
    c->log(c->env, st, cat, msg);
}

static void *mem_alloc(Instance *c, size_t size) { (void)c; return calloc(1, size); }
static void mem_free(Instance *c, void *p) { (void)c; free(p); }

#define FMI_VERSION 3
#define IS_CS(c) ((c)->kind != ME)          /* Co-Simulation or Scheduled Execution */
#define KIND_CODE(c) ((int)(c)->kind)
#ifdef CLOCK_VR
#define CS_EXTRA_STATES B(M_EVENT)
#endif
#include "wrapper_common.h"
#define HANDLE fmi3Instance
#define REAL fmi3Float64
#include "wrapper_functions.h"

/* The Co-Simulation states of the FMI 3.0 state machine besides wrapper_modes.h's; after an
 * Error the getters answer with values for debugging only (as FMI 2.0's tables and the
 * Terminated state's note say). The Initialized states of a Co-Simulation or Scheduled
 * Execution instance (Event Mode and Clock Activation Mode: the clocked form only): */
#define CS_INITIALIZED (B(M_STEP) | B(M_EVENT) | B(M_ACTIVATION))
#define GET_CS (B(M_INIT) | CS_INITIALIZED | B(M_TERMINATED) | B(M_ERROR))
#define SET_CS (B(M_INSTANTIATED) | B(M_INIT) | CS_INITIALIZED)

#ifdef CLOCK_VR
/* 0 if the variables vr[] may be got (set = 0) or set (set = 1) now, else the call is refused:
 * clocked variables only while the clock is active (Co-Simulation: in Event Mode after
 * fmi3SetClock, before fmi3UpdateDiscreteStates; Scheduled Execution: set before an
 * activation, got after one and before any set), and at any time before the run (and, for
 * debugging, after it). */
static int clock_gate(Instance *c, const char *fn, const fmi3ValueReference vr[], size_t n, int set) {
    if (B(c->mode) & (B(M_INSTANTIATED) | B(M_INIT) | B(M_TERMINATED) | B(M_ERROR))) return 0;
    for (size_t i = 0; i < n; i++) {
        const char *name;
        if (vr[i] >= N_VARS || !core_is_clocked(vr[i])) continue;
        name = VAR_NAMES[vr[i]];
        if (c->kind == SE) {
            if (set || c->d.clk.fresh) continue;
            fail(c, fn, "%s is clocked by the clock sample: get it after fmi3ActivateModelPartition, not before the "
                        "first activation nor after a set without an activation in between", name);
            return 1;
        }
        if (c->mode == M_EVENT && c->d.clk.active) continue;
        fail(c, fn, "%s is clocked by the clock sample, which is not active (%s): %s it in Event Mode after "
                    "fmi3SetClock activated the clock, before fmi3UpdateDiscreteStates", name, mode_name(c->mode),
             set ? "set" : "get");
        return 1;
    }
    return 0;
}
#define CLOCK_GATE(fn, vr, n, set) do { if (clock_gate(c, fn, vr, n, set)) return fmi3Error; } while (0)
/* Scheduled Execution: after a set, no get before the next activation */
static fmi3Status after_set(Instance *c, fmi3Status st, size_t n) {
    if (st == fmi3OK && c->kind == SE && n) c->d.clk.fresh = 0;
    return st;
}
#define AFTER_SET(st, n) after_set(c, st, n)
#else
#define CLOCK_GATE(fn, vr, n, set) do { } while (0)
#define AFTER_SET(st, n) (st)
#endif

/* ------------------------------------------------------------------ lifecycle */
const char *fmi3GetVersion(void) { return fmi3Version; }

/* A refused instantiation: the message (if logging is on and there is a callback), NULL. */
static fmi3Instance refuse_instance(fmi3Boolean logging, fmi3InstanceEnvironment env, fmi3LogMessageCallback log,
                                    const char *fn, const char *why) {
    char msg[ERRLEN + 100];
    if (logging && log) {
        snprintf(msg, sizeof msg, "%s: %s", fn, why);
        log(env, fmi3Error, "logStatusError", msg);
    }
    return NULL;
}

static Instance *instantiate(Kind kind, const char *fn, fmi3String name, fmi3String token, fmi3Boolean logging,
                             fmi3InstanceEnvironment env, fmi3LogMessageCallback log) {
    Instance *c;
    char why[ERRLEN];
    if (!name || !name[strspn(name, " \t\r\n")])
        return refuse_instance(logging, env, log, fn, "instanceName must be a non-empty string");
    if (!token || strcmp(token, MODEL_GUID) != 0) {
        snprintf(why, sizeof why, "instantiationToken %.80s does not match this FMU's %s", token ? token : "(null)",
                 MODEL_GUID);
        return refuse_instance(logging, env, log, fn, why);
    }
    c = (Instance *)calloc(1, sizeof(Instance));
    if (!c) return refuse_instance(logging, env, log, fn, "out of memory");
    c->env = env;
    c->log = log;
    c->cats = logging ? CAT_ALL_BITS : 0u;
    c->kind = kind;
    core_defaults(&c->d);
    c->mode = M_INSTANTIATED;
    return c;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String name, fmi3String token, fmi3String res,
                                          fmi3Boolean visible, fmi3Boolean logging,
                                          fmi3InstanceEnvironment env, fmi3LogMessageCallback log) {
    (void)res; (void)visible;
    if (!CORE_HAS_ME)
        return refuse_instance(logging, env, log, "fmi3InstantiateModelExchange",
                               "this FMU has no Model Exchange interface");
    return instantiate(ME, "fmi3InstantiateModelExchange", name, token, logging, env, log);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String name, fmi3String token, fmi3String res,
                                         fmi3Boolean visible, fmi3Boolean logging,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference req[], size_t nreq,
                                         fmi3InstanceEnvironment env, fmi3LogMessageCallback log,
                                         fmi3IntermediateUpdateCallback upd) {
    const char *fn = "fmi3InstantiateCoSimulation";
    (void)res; (void)visible; (void)earlyReturnAllowed; (void)req; (void)upd;
#ifdef CLOCK_VR
    if (!eventModeUsed)
        return refuse_instance(logging, env, log, fn,
                               "eventModeUsed = false, but this FMU has clocks: the standard requires eventModeUsed = true");
#else
    if (eventModeUsed)
        return refuse_instance(logging, env, log, fn,
                               "eventModeUsed = true, but this FMU has no Event Mode in Co-Simulation (hasEventMode = false)");
#endif
    if (nreq)
        return refuse_instance(logging, env, log, fn,
                               "requiredIntermediateVariables given, but no variable can be accessed in Intermediate "
                               "Update Mode (providesIntermediateUpdate = false)");
    return instantiate(CS, fn, name, token, logging, env, log);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String name, fmi3String token, fmi3String res,
                                               fmi3Boolean visible, fmi3Boolean logging,
                                               fmi3InstanceEnvironment env, fmi3LogMessageCallback log,
                                               fmi3ClockUpdateCallback cu, fmi3LockPreemptionCallback lp,
                                               fmi3UnlockPreemptionCallback up) {
    (void)res; (void)visible; (void)cu; (void)lp; (void)up;   /* no output or countdown clocks: no clock update */
#ifdef CLOCK_VR
    return instantiate(SE, "fmi3InstantiateScheduledExecution", name, token, logging, env, log);
#else
    (void)name; (void)token;
    return refuse_instance(logging, env, log, "fmi3InstantiateScheduledExecution",
                           "this FMU has no Scheduled Execution interface");
#endif
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance inst, fmi3Boolean tolDef, fmi3Float64 tol,
                                       fmi3Float64 start, fmi3Boolean stopDef, fmi3Float64 stop) {
    const char *fn = "fmi3EnterInitializationMode";
    ALLOW(fn, B(M_INSTANTIATED), B(M_INSTANTIATED));
    if (start_experiment(c, fn, tolDef, tol, start, stopDef, stop) != fmi3OK) return fmi3Error;
    c->mode = M_INIT;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance inst) {
    ALLOW("fmi3ExitInitializationMode", B(M_INIT), B(M_INIT));
#ifdef CLOCK_VR
    return exit_initialization(c, "fmi3ExitInitializationMode",   /* Co-Simulation: eventModeUsed = true */
                               c->kind == SE ? M_ACTIVATION : M_EVENT);
#else
    return exit_initialization(c, "fmi3ExitInitializationMode",   /* Co-Simulation without Event Mode */
                               c->kind == CS ? M_STEP : M_EVENT);
#endif
}

fmi3Status fmi3EnterEventMode(fmi3Instance inst) {
    ALLOW("fmi3EnterEventMode", CS_RUN, B(M_CONT));
#ifndef CLOCK_VR
    if (IS_CS(c))
        return fail(c, "fmi3EnterEventMode", "this Co-Simulation instance has no Event Mode (hasEventMode = false)");
#endif
    c->mode = M_EVENT;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance inst) {
    ALLOW("fmi3Terminate", CS_INITIALIZED, ME_RUN);
    c->mode = M_TERMINATED;
    return fmi3OK;
}

/* ------------------------------------------------------------------ values */
/* Every variable is a scalar: nValues must equal nValueReferences. */
#define VALUES(fn, vr, n, v, nv) do { ARRAY(fn, vr, n); ARRAY(fn, v, nv); \
    if ((nv) != (n)) return fail(c, fn, "nValues = %zu differs from nValueReferences = %zu (all variables are scalars)", \
                                 (size_t)(nv), (size_t)(n)); } while (0)

/* The getter GET and setter SET of the type T over the shared calls get and set: clocked
 * variables only while the clock allows. */
#define VALUE_FUNCTIONS(T, GET, SET, me_mask, get, set)                                                  \
    fmi3Status GET(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, T v[], size_t nv) {       \
        ALLOW(#GET, GET_CS, GET_ME);                                                                     \
        VALUES(#GET, vr, n, v, nv);                                                                      \
        CLOCK_GATE(#GET, vr, n, 0);                                                                      \
        return get(c, #GET, vr, n, v);                                                                   \
    }                                                                                                    \
    fmi3Status SET(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, const T v[], size_t nv) { \
        ALLOW(#SET, SET_CS, me_mask);                                                                    \
        VALUES(#SET, vr, n, v, nv);                                                                      \
        CLOCK_GATE(#SET, vr, n, 1);                                                                      \
        return AFTER_SET(set(c, #SET, vr, n, v), n);                                                     \
    }

/* Integer-valued variables: the core says which width each has (Enumerations use Int64). */
INT_CALLS(fmi3Int64, INT_64)
INT_CALLS(fmi3Int32, INT_32)
VALUE_FUNCTIONS(fmi3Float64, fmi3GetFloat64, fmi3SetFloat64, SET_REAL_ME, get_reals, set_reals)
VALUE_FUNCTIONS(fmi3Int64, fmi3GetInt64, fmi3SetInt64, SET_DISCRETE_ME, get_fmi3Int64, set_fmi3Int64)
VALUE_FUNCTIONS(fmi3Int32, fmi3GetInt32, fmi3SetInt32, SET_DISCRETE_ME, get_fmi3Int32, set_fmi3Int32)
VALUE_FUNCTIONS(fmi3Boolean, fmi3GetBoolean, fmi3SetBoolean, SET_DISCRETE_ME, get_booleans, set_booleans)

/* Types this FMU has no variables of. */
#define NONE_GET(fn, T) fmi3Status fn(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, T v[], size_t nv) { \
    ALLOW(#fn, GET_CS, GET_ME); VALUES(#fn, vr, n, v, nv); \
    return n ? fail(c, #fn, "no variable of this type has value reference %u", vr[0]) : fmi3OK; }
#define NONE_SET(fn, T, ME_MASK) fmi3Status fn(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, const T v[], size_t nv) { \
    ALLOW(#fn, SET_CS, ME_MASK); VALUES(#fn, vr, n, v, nv); \
    return n ? fail(c, #fn, "no variable of this type has value reference %u", vr[0]) : fmi3OK; }
NONE_GET(fmi3GetFloat32, fmi3Float32) NONE_SET(fmi3SetFloat32, fmi3Float32, SET_REAL_ME)
NONE_GET(fmi3GetInt8, fmi3Int8)       NONE_SET(fmi3SetInt8, fmi3Int8, SET_DISCRETE_ME)
NONE_GET(fmi3GetUInt8, fmi3UInt8)     NONE_SET(fmi3SetUInt8, fmi3UInt8, SET_DISCRETE_ME)
NONE_GET(fmi3GetInt16, fmi3Int16)     NONE_SET(fmi3SetInt16, fmi3Int16, SET_DISCRETE_ME)
NONE_GET(fmi3GetUInt16, fmi3UInt16)   NONE_SET(fmi3SetUInt16, fmi3UInt16, SET_DISCRETE_ME)
NONE_GET(fmi3GetUInt32, fmi3UInt32)   NONE_SET(fmi3SetUInt32, fmi3UInt32, SET_DISCRETE_ME)
NONE_GET(fmi3GetUInt64, fmi3UInt64)   NONE_SET(fmi3SetUInt64, fmi3UInt64, SET_DISCRETE_ME)
NONE_GET(fmi3GetString, fmi3String)   NONE_SET(fmi3SetString, fmi3String, SET_DISCRETE_ME)

fmi3Status fmi3GetBinary(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, size_t sizes[], fmi3Binary v[], size_t nv) {
    ALLOW("fmi3GetBinary", GET_CS, GET_ME);
    VALUES("fmi3GetBinary", vr, n, v, nv);
    ARRAY("fmi3GetBinary", sizes, nv);
    return n ? fail(c, "fmi3GetBinary", "no Binary variable has value reference %u", vr[0]) : fmi3OK;
}
fmi3Status fmi3SetBinary(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, const size_t sizes[], const fmi3Binary v[], size_t nv) {
    ALLOW("fmi3SetBinary", SET_CS, SET_DISCRETE_ME);
    VALUES("fmi3SetBinary", vr, n, v, nv);
    ARRAY("fmi3SetBinary", sizes, nv);
    return n ? fail(c, "fmi3SetBinary", "no Binary variable has value reference %u", vr[0]) : fmi3OK;
}
/* Clocks: Event Mode only (Scheduled Execution has none: fmi3SetClock must not be called there). */
#ifdef CLOCK_VR
fmi3Status fmi3GetClock(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, fmi3Clock v[]) {
    ALLOW("fmi3GetClock", B(M_EVENT), B(M_EVENT));
    ARRAY("fmi3GetClock", vr, n); ARRAY("fmi3GetClock", v, n);
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != CLOCK_VR) return fail(c, "fmi3GetClock", "no Clock variable has value reference %u", vr[i]);
        v[i] = c->d.clk.active ? fmi3ClockActive : fmi3ClockInactive;
    }
    return fmi3OK;
}
fmi3Status fmi3SetClock(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, const fmi3Clock v[]) {
    const char *fn = "fmi3SetClock";
    double t;
    ALLOW(fn, B(M_EVENT), B(M_EVENT));
    ARRAY(fn, vr, n); ARRAY(fn, v, n);
    t = core_time(&c->d);
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != CLOCK_VR)
            return fail(c, fn, "no input Clock has value reference %u (the clock sample has %u)", vr[i], (unsigned)CLOCK_VR);
        if (!v[i]) return fail(c, fn, "the clock sample cannot be deactivated (canBeDeactivated = false)");
    }
    if (!n || c->d.clk.active) return fmi3OK;
    switch (core_clock_due(&c->d, t)) {
    case 1: break;
    case 0: return fail(c, fn, "the clock sample is not due at t = %.17g s: its next activation is at %.17g s", t,
                        core_clock_next(&c->d));
    default: return fail(c, fn, "the activation of the clock sample at %.17g s was not made (the FMU is at t = %.17g s)",
                         core_clock_next(&c->d), t);
    }
    BEGIN_CHANGE(c);
    if (core_clock_begin(&c->wk, &c->d, c->err)) return undo(c, fn);
    c->d.clk.active = 1;
    return fmi3OK;
}
#else
fmi3Status fmi3GetClock(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, fmi3Clock v[]) {
    ALLOW("fmi3GetClock", B(M_EVENT), B(M_EVENT));
    ARRAY("fmi3GetClock", vr, n); ARRAY("fmi3GetClock", v, n);
    return n ? fail(c, "fmi3GetClock", "no Clock variable has value reference %u", vr[0]) : fmi3OK;
}
fmi3Status fmi3SetClock(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, const fmi3Clock v[]) {
    ALLOW("fmi3SetClock", B(M_EVENT), B(M_EVENT));
    ARRAY("fmi3SetClock", vr, n); ARRAY("fmi3SetClock", v, n);
    return n ? fail(c, "fmi3SetClock", "no Clock variable has value reference %u", vr[0]) : fmi3OK;
}
#endif

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance inst, fmi3ValueReference vr, size_t *n) {
    ALLOW("fmi3GetNumberOfVariableDependencies", LIVE, LIVE); (void)vr; (void)n;
    return fail(c, "fmi3GetNumberOfVariableDependencies", "not supported: read the dependencies from the ModelStructure");
}
fmi3Status fmi3GetVariableDependencies(fmi3Instance inst, fmi3ValueReference dep, size_t ei[], fmi3ValueReference ind[],
                                       size_t eii[], fmi3DependencyKind kinds[], size_t n) {
    ALLOW("fmi3GetVariableDependencies", LIVE, LIVE); (void)dep; (void)ei; (void)ind; (void)eii; (void)kinds; (void)n;
    return fail(c, "fmi3GetVariableDependencies", "not supported: read the dependencies from the ModelStructure");
}

/* ------------------------------------------------------------------ FMU state */
FMU_STATE_FUNCTIONS(fmi3FMUState, fmi3GetFMUState, fmi3SetFMUState, fmi3FreeFMUState, fmi3SerializedFMUStateSize,
                    fmi3SerializeFMUState, fmi3DeserializeFMUState)

/* ------------------------------------------------------------------ derivatives */
/* The directional derivative, or (adjoint) the adjoint one, of scalar variables. */
static fmi3Status derivative(Instance *c, const char *fn, int adjoint, const fmi3ValueReference unk[], size_t nU,
                             const fmi3ValueReference kn[], size_t nK, const fmi3Float64 seed[], size_t nSeed,
                             fmi3Float64 sens[], size_t nSens) {
    if (!CORE_HAS_DERIVATIVES) return fail(c, fn, "not provided by this FMU");
    ARRAY(fn, unk, nU); ARRAY(fn, kn, nK); ARRAY(fn, seed, nSeed); ARRAY(fn, sens, nSens);
    if (!adjoint) {
        if (nSeed != nK || nSens != nU) return fail(c, fn, "nSeed must equal nKnowns and nSensitivity nUnknowns (scalar variables)");
        return core(c, fn, core_directional(&c->wk, &c->d, unk, nU, kn, nK, seed, sens, c->err));
    }
    /* v^T J: accumulate row by row with the directional derivative of each known */
    if (nSeed != nU || nSens != nK) return fail(c, fn, "nSeed must equal nUnknowns and nSensitivity nKnowns (scalar variables)");
    if (nU > 256) return fail(c, fn, "too many unknowns (at most 256)");
    for (size_t k = 0; k < nK; k++) {
        double one = 1.0, col[256];
        if (core_directional(&c->wk, &c->d, unk, nU, &kn[k], 1, &one, col, c->err)) return core(c, fn, 1);
        sens[k] = 0;
        for (size_t i = 0; i < nU; i++) sens[k] += seed[i] * col[i];
    }
    return fmi3OK;
}
#define DERIVATIVE_FUNCTION(fn, adjoint)                                                                        \
    fmi3Status fn(fmi3Instance inst, const fmi3ValueReference unk[], size_t nU, const fmi3ValueReference kn[],  \
                  size_t nK, const fmi3Float64 seed[], size_t nSeed, fmi3Float64 sens[], size_t nSens) {        \
        ALLOW(#fn, GET_CS, GET_ME);                                                                             \
        return derivative(c, #fn, adjoint, unk, nU, kn, nK, seed, nSeed, sens, nSens);                          \
    }
DERIVATIVE_FUNCTION(fmi3GetDirectionalDerivative, 0)
DERIVATIVE_FUNCTION(fmi3GetAdjointDerivative, 1)

/* ------------------------------------------------------------------ configuration, clocks: not used */
fmi3Status fmi3EnterConfigurationMode(fmi3Instance inst) {
    ALLOW("fmi3EnterConfigurationMode", B(M_INSTANTIATED) | CS_RUN, B(M_INSTANTIATED) | B(M_EVENT));
    return fail(c, "fmi3EnterConfigurationMode", "this FMU has no structural parameters");
}
fmi3Status fmi3ExitConfigurationMode(fmi3Instance inst) {
    ALLOW("fmi3ExitConfigurationMode", ANY, ANY);
    return fail(c, "fmi3ExitConfigurationMode", "not in Configuration Mode (this FMU has no structural parameters)");
}
#ifdef CLOCK_VR
/* The constant clock sample: its interval and shift may be asked in Initialization Mode, Event
 * Mode and Clock Activation Mode, in decimal form only; they cannot be set. */
#define CLOCK_ASK (B(M_INIT) | B(M_EVENT) | B(M_ACTIVATION))
static int clock_refs(Instance *c, const char *fn, const fmi3ValueReference vr[], size_t n) {
    for (size_t i = 0; i < n; i++)
        if (vr[i] != CLOCK_VR) {
            fail(c, fn, "no Clock variable has value reference %u (the clock sample has %u)", vr[i], (unsigned)CLOCK_VR);
            return 1;
        }
    return 0;
}
fmi3Status fmi3GetIntervalDecimal(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, fmi3Float64 iv[],
                                  fmi3IntervalQualifier q[]) {
    ALLOW("fmi3GetIntervalDecimal", CLOCK_ASK, CLOCK_ASK);
    ARRAY("fmi3GetIntervalDecimal", vr, n); ARRAY("fmi3GetIntervalDecimal", iv, n); ARRAY("fmi3GetIntervalDecimal", q, n);
    if (clock_refs(c, "fmi3GetIntervalDecimal", vr, n)) return fmi3Error;
    for (size_t i = 0; i < n; i++) { iv[i] = CLOCK_INTERVAL; q[i] = fmi3IntervalUnchanged; }
    return fmi3OK;
}
fmi3Status fmi3GetShiftDecimal(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, fmi3Float64 sh[]) {
    ALLOW("fmi3GetShiftDecimal", CLOCK_ASK, CLOCK_ASK);
    ARRAY("fmi3GetShiftDecimal", vr, n); ARRAY("fmi3GetShiftDecimal", sh, n);
    if (clock_refs(c, "fmi3GetShiftDecimal", vr, n)) return fmi3Error;
    for (size_t i = 0; i < n; i++) sh[i] = 0.0;
    return fmi3OK;
}
/* why the other clock functions are refused */
#define NO_FRACTION "the clock sample has no fraction form (supportsFraction = false)"
#define NO_SETTING "the clock sample is constant: its interval and shift cannot be set"
#else
#define NO_FRACTION "this FMU has no clocks"
#define NO_SETTING NO_FRACTION
#endif
/* A clock function refused in every state, with the reason why. */
#define REFUSED(fn, why, ...) fmi3Status fn(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, __VA_ARGS__) { \
    ALLOW(#fn, ANY, ANY); (void)vr; (void)n; return fail(c, #fn, why); }
#ifndef CLOCK_VR
REFUSED(fmi3GetIntervalDecimal, NO_FRACTION, fmi3Float64 iv[], fmi3IntervalQualifier q[])
REFUSED(fmi3GetShiftDecimal, NO_FRACTION, fmi3Float64 sh[])
#endif
REFUSED(fmi3GetIntervalFraction, NO_FRACTION, fmi3UInt64 cn[], fmi3UInt64 rs[], fmi3IntervalQualifier q[])
REFUSED(fmi3GetShiftFraction, NO_FRACTION, fmi3UInt64 cn[], fmi3UInt64 rs[])
REFUSED(fmi3SetIntervalDecimal, NO_SETTING, const fmi3Float64 iv[])
REFUSED(fmi3SetIntervalFraction, NO_SETTING, const fmi3UInt64 cn[], const fmi3UInt64 rs[])
REFUSED(fmi3SetShiftDecimal, NO_SETTING, const fmi3Float64 sh[])
REFUSED(fmi3SetShiftFraction, NO_SETTING, const fmi3UInt64 cn[], const fmi3UInt64 rs[])

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance inst) {
    ALLOW("fmi3EvaluateDiscreteStates", ANY, ANY);
    return fail(c, "fmi3EvaluateDiscreteStates", "not provided by this FMU (providesEvaluateDiscreteStates = false)");
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance inst, fmi3Boolean *need, fmi3Boolean *term, fmi3Boolean *nom,
                                    fmi3Boolean *vals, fmi3Boolean *nextDef, fmi3Float64 *next) {
    const char *fn = "fmi3UpdateDiscreteStates";
    ALLOW(fn, B(M_EVENT), B(M_EVENT));
    NOT_NULL(fn, need); NOT_NULL(fn, term); NOT_NULL(fn, nom); NOT_NULL(fn, vals); NOT_NULL(fn, nextDef);
    NOT_NULL(fn, next);
    *need = fmi3False; *term = fmi3False; *nom = fmi3False; *vals = fmi3False; *nextDef = fmi3False; *next = 0;
#ifdef CLOCK_VR
    if (c->d.clk.active) {                   /* the end of the activation: its update is committed */
        BEGIN_CHANGE(c);
        if (core_clock_end(&c->wk, &c->d, c->err)) return undo(c, fn);
        c->d.clk.active = 0;
    }
#endif
    return fmi3OK;
}

/* ------------------------------------------------------------------ Model Exchange */
COMPLETED_INTEGRATOR_STEP(enter, term)
GET_DERIVATIVES(fmi3GetContinuousStateDerivatives)

fmi3Status fmi3GetEventIndicators(fmi3Instance inst, fmi3Float64 ind[], size_t ni) {
    ALLOW("fmi3GetEventIndicators", 0, GET_ME); (void)ind;
    return ni ? fail(c, "fmi3GetEventIndicators", "nEventIndicators = %zu, this model has none", ni) : fmi3OK;
}

GET_NOMINALS(GET_ME)

/* Instantiated and Event Mode (the standard's tables; also the configuration modes). */
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance inst, size_t *n) {
    ALLOW("fmi3GetNumberOfEventIndicators", 0, B(M_INSTANTIATED) | B(M_EVENT));
    NOT_NULL("fmi3GetNumberOfEventIndicators", n);
    *n = 0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance inst, size_t *n) {
    ALLOW("fmi3GetNumberOfContinuousStates", 0, B(M_INSTANTIATED) | B(M_EVENT));
    NOT_NULL("fmi3GetNumberOfContinuousStates", n);
    *n = CORE_NX;
    return fmi3OK;
}

/* ------------------------------------------------------------------ Co-Simulation */
/* From Event Mode, which a Co-Simulation instance of this FMU never enters. */
fmi3Status fmi3EnterStepMode(fmi3Instance inst) {
    ALLOW("fmi3EnterStepMode", B(M_EVENT), 0);
#ifdef CLOCK_VR
    if (c->d.clk.active)
        return fail(c, "fmi3EnterStepMode", "the clock sample is active: fmi3UpdateDiscreteStates must end its "
                                            "super-dense instant first");
#endif
    c->mode = M_STEP;
    return fmi3OK;
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance inst, const fmi3ValueReference vr[], size_t n,
                                    const fmi3Int32 orders[], fmi3Float64 v[], size_t nv) {
    ALLOW("fmi3GetOutputDerivatives", CS_RUN | B(M_TERMINATED) | B(M_ERROR), 0); (void)vr; (void)orders; (void)v; (void)nv;
    return n ? fail(c, "fmi3GetOutputDerivatives", "output derivatives are not provided (maxOutputDerivativeOrder = 0)") : fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance inst, fmi3Float64 t, fmi3Float64 h, fmi3Boolean noSetPrior,
                      fmi3Boolean *eventNeeded, fmi3Boolean *term, fmi3Boolean *early, fmi3Float64 *last) {
    const char *fn = "fmi3DoStep";
    ALLOW(fn, CS_RUN, 0); (void)noSetPrior;
    NOT_NULL(fn, eventNeeded); NOT_NULL(fn, term); NOT_NULL(fn, early); NOT_NULL(fn, last);
    *eventNeeded = fmi3False; *term = fmi3False; *early = fmi3False;
#ifdef CLOCK_VR
    /* the clocked form: time advances, the activations run in Event Mode */
    *last = core_time(&c->d);
    if (!isfinite(t) || !(h > 0) || !isfinite(h) || !isfinite(t + h))
        return fail(c, fn, "currentCommunicationPoint %g and communicationStepSize %g must be finite, the step > 0", t, h);
    if (off_time(t, core_time(&c->d)))
        return fail(c, fn, "currentCommunicationPoint %.17g differs from the FMU time %.17g", t, core_time(&c->d));
    if (core_clock_due(&c->d, t))
        return fail(c, fn, "the activation of the clock sample at %.17g s was not made: enter Event Mode and activate "
                           "it with fmi3SetClock before stepping on", core_clock_next(&c->d));
    if (core_clock_due(&c->d, t + h) == 2)
        return fail(c, fn, "the step from %.17g s to %.17g s passes the activation of the clock sample at %.17g s: "
                           "step to it and activate it in Event Mode", t, t + h, core_clock_next(&c->d));
    core_set_time(&c->d, t + h);
    *last = t + h;
    return fmi3OK;
#endif
    fmi3Status st = do_step(c, fn, t, h);
    *last = core_time(&c->d);
    return st;
}

#ifdef CLOCK_VR
fmi3Status fmi3ActivateModelPartition(fmi3Instance inst, fmi3ValueReference clk, fmi3Float64 t) {
    const char *fn = "fmi3ActivateModelPartition";
    ALLOW(fn, B(M_ACTIVATION), 0);
    if (clk != CLOCK_VR)
        return fail(c, fn, "no input Clock has value reference %u (the clock sample has %u)", clk, (unsigned)CLOCK_VR);
    if (!isfinite(t)) return fail(c, fn, "activationTime %g is not finite", t);
    switch (core_clock_due(&c->d, t)) {
    case 1: break;
    case 0: return fail(c, fn, "the clock sample is not due at t = %.17g s: its next activation is at %.17g s", t,
                        core_clock_next(&c->d));
    default: return fail(c, fn, "activationTime %.17g s skips the activation of the clock sample at %.17g s", t,
                         core_clock_next(&c->d));
    }
    BEGIN_CHANGE(c);
    core_set_time(&c->d, t);
    if (core_clock_begin(&c->wk, &c->d, c->err) || core_clock_end(&c->wk, &c->d, c->err)) return undo(c, fn);
    c->d.clk.fresh = 1;
    return fmi3OK;
}
#else
fmi3Status fmi3ActivateModelPartition(fmi3Instance inst, fmi3ValueReference clk, fmi3Float64 t) {
    ALLOW("fmi3ActivateModelPartition", ANY, ANY); (void)clk; (void)t;
    return fail(c, "fmi3ActivateModelPartition", "Scheduled Execution is not supported by this FMU");
}
#endif
