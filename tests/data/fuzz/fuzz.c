/* pendulum-cosim call-sequence fuzzer for the project's own FMUs (FMI 2.0 and 3.0, Co-Simulation
 * and Model Exchange), built with the FMU's library under AddressSanitizer and
 * UndefinedBehaviorSanitizer (tests/testkit/fuzz_run.py builds both and runs this).
 *
 *   fuzz lib=PATH fmi=2|3 cs=0|1 me=0|1 dd=0|1 token=TOKEN vars=FILE seed=S first=I count=N
 *        [calls=60] [timeout=10] [trace=0]
 *   fuzz lib=... fmi=... cs=... me=... dd=... token=... vars=... case=NAME   (cases.c)
 *
 * Runs sequences first .. first + count - 1, sequence i from its own generator seeded with
 * (seed, i), so that any one replays alone (first=i count=1 trace=1). Each sequence drives up
 * to 8 instances at once through random calls: most legal in the state the model holds for
 * the instance, with legal arguments, the others in any state (wrong state, twice, out of
 * order, after an Error), with hostile arguments (NaN, inf, huge and denormal values, zero,
 * negative and huge step sizes, unknown value references, wrong counts, NULL pointers, a NULL
 * logger, FMU states that were freed or belong to another instance, changed serialised
 * states, failing memory allocation), and bursts of instantiate/free.
 *
 * Checked on every call, against the model (fuzz_common.h, the tables below):
 *   - a call the standard forbids (state, interface, arguments) returns Error;
 *   - a legal call with legal arguments returns OK (unless the instance accepted a hostile
 *     value before, after which the model allows either);
 *   - an Error comes with a log message naming the function when logging is on (FMI 2.0: a
 *     logger is given; FMI 3.0: loggingOn or the logStatusError category); FMI 3.0 with logging
 *     off: the log callback is never called;
 *   - no call takes longer than the time limit (SIGALRM: a hang), no Fatal, no crash and no
 *     sanitizer report (the sanitizers end the process; a death callback names the call).
 * The first violation prints the sequence, the call and the trace of the sequence, and exits 1.
 * The last line is a summary: FUZZ sequences=... calls=... illegal=... (see main).
 *
 * VARFILE has one variable a line: vr type causality variability initial start flags, where
 * type is R (Real / Float64), I (Integer / Int32), L (Enumeration: Int64 in FMI 3.0), B
 * (Boolean), K (Clock); causality p(arameter) c(alculatedParameter) i(nput) o(utput) l(ocal)
 * t (independent); variability c(onstant) f(ixed) t(unable) d(iscrete) n (continuous); initial
 * e(xact) a(pprox) c(alculated) - (none); flags S (a continuous state), D (a derivative),
 * K (clocked by the clock), -.
 *
 * Clocked FMUs (FMI 3.0; arguments clock=VR interval=T): the FMU's one input clock, constant,
 * interval T, first activation at the start time, clocks the variables flagged K. The model
 * then follows the standard's clock rules (the clocked rows of the table, CLOCK_ROWS, and
 * the clock state of each instance): Co-Simulation instances need eventModeUsed = true and
 * enter Event Mode after initialisation; fmi3SetClock is legal only when the activation is due
 * (t0 + n T within 1e-6 T of the time) or the clock already active; clocked variables are set
 * and got in Event Mode only while the clock is active, never in Step Mode; fmi3EnterStepMode
 * only after fmi3UpdateDiscreteStates ended the activation; fmi3DoStep neither from a due
 * activation nor past the next one. Scheduled Execution instances (Clock Activation Mode)
 * activate with fmi3ActivateModelPartition(clock, t0 + n T) only, set inputs before and get
 * clocked variables after an activation (not after a set). fmi3GetIntervalDecimal answers T,
 * fmi3IntervalUnchanged.
 */
#define _POSIX_C_SOURCE 200809L
#include <dlfcn.h>
#include <signal.h>
#include <stdarg.h>
#include <sys/time.h>
#include <unistd.h>
#include "fmi2FunctionTypes.h"
#include "fmi3FunctionTypes.h"
#include "fuzz_common.h"

extern void __sanitizer_set_death_callback(void (*)(void)) __attribute__((weak));

/* ------------------------------------------------------------------ the state tables
 * One table for both versions (a function's name says its version).
 *
 * FMI 2.0: the tables of sections 3.2.3 (Model Exchange) and 4.2.4 (Co-Simulation), for the
 * states these FMUs reach (no asynchronous doStep: no stepInProgress, stepFailed or
 * stepCanceled; stepComplete is S). Column X is the tables' "error" state: the getters
 * (note 7: values for debugging only), the FMU-state functions, fmi2Reset, fmi2FreeInstance
 * and fmi2SetDebugLogging.
 *
 * FMI 3.0: the allowed function calls of each state (sections 2.3.1 to 2.3.9, 3.2.1, 4.2.1),
 * for an FMU without Event Mode in Co-Simulation, clocks, structural parameters, intermediate
 * update and evaluateDiscreteStates (all Error: the empty rows). After an Error (X) the
 * simulation must not go on: fmi3FreeInstance, fmi3Reset, fmi3SetDebugLogging, the FMU-state
 * functions (a saved state may be restored) and the getters (values for debugging only). */
static const Row STATE_TABLE[] = {
    {"fmi2SetDebugLogging", "INSTX", "INECTX"},
    {"fmi2SetupExperiment", "I", "I"},
    {"fmi2EnterInitializationMode", "I", "I"},
    {"fmi2ExitInitializationMode", "N", "N"},
    {"fmi2Terminate", "S", "EC"},
    {"fmi2Reset", "INSTX", "INECTX"},
    {"fmi2GetReal", "NSTX", "NECTX"},
    {"fmi2GetInteger", "NSTX", "NECTX"},
    {"fmi2GetBoolean", "NSTX", "NECTX"},
    {"fmi2GetString", "NSTX", "NECTX"},
    {"fmi2SetReal", "INS", "INEC"},
    {"fmi2SetInteger", "INS", "INE"},
    {"fmi2SetBoolean", "INS", "INE"},
    {"fmi2SetString", "INS", "INE"},
    {"fmi2GetFMUstate", "INST", "INECT"},
    {"fmi2SetFMUstate", "INSTX", "INECTX"},
    {"fmi2FreeFMUstate", "INSTX", "INECTX"},
    {"fmi2SerializedFMUstateSize", "INSTX", "INECTX"},
    {"fmi2SerializeFMUstate", "INSTX", "INECTX"},
    {"fmi2DeSerializeFMUstate", "INSTX", "INECTX"},
    {"fmi2GetDirectionalDerivative", "NSTX", "NECTX"},
    {"fmi2EnterEventMode", "-", "EC"},
    {"fmi2NewDiscreteStates", "-", "E"},
    {"fmi2EnterContinuousTimeMode", "-", "E"},
    {"fmi2CompletedIntegratorStep", "-", "C"},
    {"fmi2SetTime", "-", "C"},     /* Event Mode (note 8): a pure discrete-time FMU only */
    {"fmi2SetContinuousStates", "-", "C"},
    {"fmi2GetDerivatives", "-", "NECTX"},
    {"fmi2GetEventIndicators", "-", "NECTX"},
    {"fmi2GetContinuousStates", "-", "NECTX"},
    {"fmi2GetNominalsOfContinuousStates", "-", "INECTX"},
    {"fmi2SetRealInputDerivatives", "INS", "-"},
    {"fmi2GetRealOutputDerivatives", "STX", "-"},
    {"fmi2DoStep", "S", "-"},
    {"fmi2CancelStep", "", "-"},   /* stepInProgress only: never reached */
    {"fmi2GetStatus", "", "-"},    /* the status functions: only after Pending or Discard */
    {"fmi2GetRealStatus", "", "-"},
    {"fmi2GetIntegerStatus", "", "-"},
    {"fmi2GetBooleanStatus", "", "-"},
    {"fmi2GetStringStatus", "", "-"},
    {"fmi3SetDebugLogging", "INSTX", "INECTX"},
    {"fmi3EnterInitializationMode", "I", "I"},
    {"fmi3ExitInitializationMode", "N", "N"},
    {"fmi3EnterEventMode", "", "C"},          /* CS: only with eventModeUsed */
    {"fmi3Terminate", "S", "EC"},
    {"fmi3Reset", "INSTX", "INECTX"},
    {"fmi3GetFloat64", "NSTX", "NECTX"},
    {"fmi3GetInt32", "NSTX", "NECTX"},
    {"fmi3GetInt64", "NSTX", "NECTX"},
    {"fmi3GetBoolean", "NSTX", "NECTX"},
    {"fmi3GetString", "NSTX", "NECTX"},
    {"fmi3GetFloat32", "NSTX", "NECTX"},
    {"fmi3GetUInt8", "NSTX", "NECTX"},
    {"fmi3GetBinary", "NSTX", "NECTX"},
    {"fmi3SetFloat64", "INS", "INEC"},
    {"fmi3SetFloat32", "INS", "INEC"},
    {"fmi3SetInt32", "INS", "INE"},
    {"fmi3SetInt64", "INS", "INE"},
    {"fmi3SetBoolean", "INS", "INE"},
    {"fmi3SetString", "INS", "INE"},
    {"fmi3SetUInt8", "INS", "INE"},
    {"fmi3SetBinary", "INS", "INE"},
    {"fmi3GetClock", "", "E"},
    {"fmi3SetClock", "", "E"},
    {"fmi3GetFMUState", "INST", "INECT"},
    {"fmi3SetFMUState", "INSTX", "INECTX"},
    {"fmi3FreeFMUState", "INSTX", "INECTX"},
    {"fmi3SerializedFMUStateSize", "INSTX", "INECTX"},
    {"fmi3SerializeFMUState", "INSTX", "INECTX"},
    {"fmi3DeserializeFMUState", "INSTX", "INECTX"},
    {"fmi3GetDirectionalDerivative", "NSTX", "NECTX"},
    {"fmi3GetAdjointDerivative", "NSTX", "NECTX"},
    {"fmi3EnterConfigurationMode", "", ""},   /* no structural parameters */
    {"fmi3ExitConfigurationMode", "", ""},
    {"fmi3GetIntervalDecimal", "", ""},       /* no clocks */
    {"fmi3SetShiftDecimal", "", ""},
    {"fmi3EvaluateDiscreteStates", "", ""},   /* providesEvaluateDiscreteStates = false */
    {"fmi3GetNumberOfVariableDependencies", "", ""},
    {"fmi3ActivateModelPartition", "", ""},   /* Scheduled Execution */
    {"fmi3UpdateDiscreteStates", "", "E"},
    {"fmi3EnterContinuousTimeMode", "-", "E"},
    {"fmi3CompletedIntegratorStep", "-", "C"},
    {"fmi3SetTime", "-", "C"},
    {"fmi3SetContinuousStates", "-", "C"},
    {"fmi3GetContinuousStateDerivatives", "-", "NECTX"},
    {"fmi3GetEventIndicators", "-", "NECTX"},
    {"fmi3GetContinuousStates", "-", "NECTX"},
    {"fmi3GetNominalsOfContinuousStates", "-", "NECTX"},
    {"fmi3GetNumberOfEventIndicators", "-", "IE"},
    {"fmi3GetNumberOfContinuousStates", "-", "IE"},
    {"fmi3EnterStepMode", "", "-"},           /* from Event Mode: never in CS here */
    {"fmi3GetOutputDerivatives", "STX", "-"},
    {"fmi3DoStep", "S", "-"},
    {NULL, NULL, NULL}};

/* FMI 3.0, clocked FMUs: the rows that differ (Co-Simulation with Event Mode: E; Scheduled
 * Execution: A; both use the first column, their states being disjoint but for I, N, T, X). */
static const Row CLOCK_ROWS[] = {
    {"fmi3SetDebugLogging", "INSEATX", "-"},
    {"fmi3EnterEventMode", "S", "-"},
    {"fmi3Terminate", "SEA", "-"},
    {"fmi3Reset", "INSEATX", "-"},
    {"fmi3GetFloat64", "NSEATX", "-"}, {"fmi3GetInt32", "NSEATX", "-"}, {"fmi3GetInt64", "NSEATX", "-"},
    {"fmi3GetBoolean", "NSEATX", "-"}, {"fmi3GetString", "NSEATX", "-"}, {"fmi3GetFloat32", "NSEATX", "-"},
    {"fmi3GetUInt8", "NSEATX", "-"}, {"fmi3GetBinary", "NSEATX", "-"},
    {"fmi3SetFloat64", "INSEA", "-"}, {"fmi3SetFloat32", "INSEA", "-"}, {"fmi3SetInt32", "INSEA", "-"},
    {"fmi3SetInt64", "INSEA", "-"}, {"fmi3SetBoolean", "INSEA", "-"}, {"fmi3SetString", "INSEA", "-"},
    {"fmi3SetUInt8", "INSEA", "-"}, {"fmi3SetBinary", "INSEA", "-"},
    {"fmi3GetClock", "E", "-"},
    {"fmi3SetClock", "E", "-"},
    {"fmi3GetFMUState", "INSEAT", "-"}, {"fmi3SetFMUState", "INSEATX", "-"}, {"fmi3FreeFMUState", "INSEATX", "-"},
    {"fmi3SerializedFMUStateSize", "INSEATX", "-"}, {"fmi3SerializeFMUState", "INSEATX", "-"},
    {"fmi3DeserializeFMUState", "INSEATX", "-"},
    {"fmi3GetDirectionalDerivative", "NSEATX", "-"}, {"fmi3GetAdjointDerivative", "NSEATX", "-"},
    {"fmi3GetIntervalDecimal", "NEA", "-"},
    {"fmi3ActivateModelPartition", "A", "-"},
    {"fmi3UpdateDiscreteStates", "E", "-"},
    {"fmi3EnterStepMode", "E", "-"},
    {NULL, NULL, NULL}};

/* ------------------------------------------------------------------ configuration */
#define MAXVARS 256
#define MAXINST 8
#define MAXSTATES 4096
#define MAXBLOBS 16
#define MAXTRACE 400

typedef struct { unsigned vr; char type, caus, var, init; double start; char flag; } Var;

static int V;                       /* FMI version */
static int HAS_CS, HAS_ME, HAS_DD;  /* interfaces, directional derivatives */
static const char *TOKEN;
static void *LIB;
static Var VARS[MAXVARS];
static int NVARS, NX;               /* variables, continuous states */
static int CLOCKED;                 /* a clocked FMU (arguments clock=, interval=) */
static unsigned CLOCK_VR;           /* its input clock */
static double INTERVAL;             /* its constant interval [s] */
static double TIMEOUT = 10;
static int TRACE, MAXCALLS = 60;
static uint64_t SEED;
static long long SEQ, CALL;         /* where we are (for the death callback) */
static const char *CUR_FN = "";

/* counters of the summary line */
static long long n_seq, n_calls, n_illegal, n_illegal_err, n_legal, n_legal_ok, n_any, n_inst;

/* The clock state of an instance of a clocked FMU: activations ended (n), active (Event Mode,
 * after fmi3SetClock), fresh (Scheduled Execution: activated, no set since), the start time. */
typedef struct { long long n; int active, fresh; double t0; } Clk;
typedef struct { void *h; int owner; int alive; int st; double time; int dirty; Clk clk; } StateRec;
typedef struct { unsigned char *bytes; size_t size; int cs; int st; double time; int dirty; Clk clk; } Blob;

typedef struct {
    void *h;              /* the FMU instance (NULL: none in this slot) */
    int id;               /* unique within the sequence */
    int cs;               /* Co-Simulation (else Model Exchange; 2: Scheduled Execution) */
    int st;               /* the model's state */
    int logging;          /* error messages expected (see the header) */
    int has_logger;
    int flaky;            /* FMI 2.0: the allocator fails now and then */
    int dirty;            /* accepted a hostile value: legal calls may fail */
    double time;          /* the FMU's time as the model tracks it */
    Clk clk;              /* a clocked FMU's clock state */
    char name[32];
} Inst;

static Inst INST[MAXINST];
static StateRec STATES[MAXSTATES];
static int NSTATES_HELD;
static Blob BLOBS[MAXBLOBS];
static int NBLOBS;
static int NEXT_ID;

/* ------------------------------------------------------------------ trace, violations */
static char TRACE_BUF[MAXTRACE][200];
static int NTRACE;

static void trace(const char *fmt, ...) {
    va_list ap;
    char *line = TRACE_BUF[NTRACE % MAXTRACE];
    va_start(ap, fmt);
    vsnprintf(line, 200, fmt, ap);
    va_end(ap);
    NTRACE++;
    if (TRACE) fprintf(stderr, "  %s\n", line);
}

static void print_trace(void) {
    int first = NTRACE > MAXTRACE ? NTRACE - MAXTRACE : 0;
    fprintf(stderr, "trace of sequence %lld (seed %llu):\n", SEQ, (unsigned long long)SEED);
    for (int i = first; i < NTRACE; i++) fprintf(stderr, "  %s\n", TRACE_BUF[i % MAXTRACE]);
}

static void summary(const char *result) {
    printf("FUZZ result=%s sequences=%lld calls=%lld illegal=%lld illegal_error=%lld legal=%lld legal_ok=%lld "
           "either=%lld instances=%lld\n", result, n_seq, n_calls, n_illegal, n_illegal_err, n_legal, n_legal_ok,
           n_any, n_inst);
    fflush(stdout);
}

static void violation(const char *fmt, ...) {
    va_list ap;
    char text[600];
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    fprintf(stderr, "VIOLATION seed=%llu seq=%lld call=%lld fn=%s: %s\n", (unsigned long long)SEED, SEQ, CALL,
            CUR_FN, text);
    print_trace();
    summary("violation");
    exit(1);
}

static void on_death(void) {
    fprintf(stderr, "DIED seed=%llu seq=%lld call=%lld fn=%s\n", (unsigned long long)SEED, SEQ, CALL, CUR_FN);
    print_trace();
}

static void on_alarm(int sig) {
    char msg[200];
    int n = snprintf(msg, sizeof msg, "HANG seed=%llu seq=%lld call=%lld fn=%s: no answer within the time limit\n",
                     (unsigned long long)SEED, SEQ, CALL, CUR_FN);
    (void)sig;
    if (n > 0) { ssize_t w = write(2, msg, (size_t)n); (void)w; }
    _exit(3);
}

/* ------------------------------------------------------------------ the log callbacks */
static int LOG_COUNT, LOG_NAMED, LOG_BAD_ENV;
static const void *LOG_ENV;          /* the environment the current call's instance was given */
static char LOG_LAST[300];

static void note_log(const void *env, int status, const char *msg) {
    LOG_COUNT++;
    if (env != LOG_ENV) LOG_BAD_ENV = 1;
    if (msg && strstr(msg, CUR_FN) && status >= 3) LOG_NAMED = 1;
    snprintf(LOG_LAST, sizeof LOG_LAST, "%s", msg ? msg : "(null)");
}
static void logger2(fmi2ComponentEnvironment env, fmi2String name, fmi2Status st, fmi2String cat, fmi2String msg, ...) {
    (void)name; (void)cat;
    note_log(env, (int)st, msg);
}
static void logger3(fmi3InstanceEnvironment env, fmi3Status st, fmi3String cat, fmi3String msg) {
    (void)cat;
    note_log(env, (int)st, msg);
}

/* FMI 2.0 memory: calloc/free, or one that fails now and then (a hostile environment). */
static Rng ALLOC_RNG;
static void *flaky_alloc(size_t n, size_t size) { return chance(&ALLOC_RNG, 0.2) ? NULL : calloc(n, size); }

/* ------------------------------------------------------------------ the model */
static const Row *row_of(const char *fn) {
    const Row *t = STATE_TABLE;
    if (CLOCKED)
        for (const Row *c = CLOCK_ROWS; c->name; c++)
            if (!strcmp(c->name, fn)) return c;
    for (; t->name; t++)
        if (!strcmp(t->name, fn)) return t;
    fprintf(stderr, "fuzz: %s is not in the state table\n", fn);
    exit(2);
}

/* 1 if the standard allows fn in the instance's state and interface. */
static int allowed(const Inst *in, const char *fn) {
    const Row *r = row_of(fn);
    return (letters_mask(in->cs ? r->cs : r->me) >> in->st) & 1u;
}

static void *sym(const char *name) {
    void *f = dlsym(LIB, name);
    if (!f) { fprintf(stderr, "fuzz: the library does not export %s\n", name); exit(2); }
    return f;
}
#define F2(name) ((name##TYPE *)sym(#name))
#define F3(name) ((name##TYPE *)sym(#name))
/* the name of this version's function: VFN(Reset) is "fmi2Reset" or "fmi3Reset" */
#define VFN(name) (V == 2 ? "fmi2" #name : "fmi3" #name)

/* fn, a function of the instance alone (fmi2Status fn(fmi2Component), fmi3Status
 * fn(fmi3Instance): the type of fmiXReset), called on h: its status. */
static int call_alone(const char *fn, void *h) {
    return V == 2 ? (int)((fmi2ResetTYPE *)sym(fn))(h) : (int)((fmi3ResetTYPE *)sym(fn))(h);
}

#define H(in) ((in)->h)
#define STATE_EXP(in, fn, args_exp) (allowed(in, fn) ? (args_exp) : EXP_ERR)

static struct itimerval TIMER;

static void begin(const char *fn, const Inst *in) {
    CUR_FN = fn;
    CALL++;
    n_calls++;
    LOG_COUNT = LOG_NAMED = LOG_BAD_ENV = 0;
    LOG_LAST[0] = 0;
    LOG_ENV = in;
    TIMER.it_value.tv_sec = (time_t)TIMEOUT;
    TIMER.it_value.tv_usec = (suseconds_t)((TIMEOUT - floor(TIMEOUT)) * 1e6);
    setitimer(ITIMER_REAL, &TIMER, NULL);
}

static void end(void) {
    struct itimerval off = {{0, 0}, {0, 0}};
    setitimer(ITIMER_REAL, &off, NULL);
}

static const char *status_name(int s) {
    static const char *n[] = {"OK", "Warning", "Discard", "Error", "Fatal", "Pending"};
    return s >= 0 && s <= 5 ? n[s] : "an invalid status";
}

/* The checks on one answer (see the header); moves the model to the error state on Error.
 * `in` NULL: the call had no instance (NULL handle), no message can be expected. */
static void check(Inst *in, int exp, int status, const char *args) {
    int logged_expected;
    if (in && in->dirty && exp == EXP_OK) exp = EXP_ANY;
    trace("%s[%d %s] %s -> %s (expected %s)%s%s", CUR_FN, in ? in->id : -1, in ? STATE_NAMES[in->st] : "-",
          args, status_name(status), EXP_NAMES[exp], LOG_COUNT ? " log: " : "", LOG_COUNT ? LOG_LAST : "");
    if (exp == EXP_ERR) n_illegal++;
    else if (exp == EXP_OK) n_legal++;
    else n_any++;
    if (status == 4) violation("Fatal returned");
    if (status != 0 && status != 3) violation("status %s (%d): these FMUs answer OK or Error", status_name(status), status);
    if (exp == EXP_ERR && status == 0) violation("a call the standard forbids was answered OK (%s)", args);
    if (exp == EXP_OK && status != 0)
        violation("a legal call with legal arguments was answered %s (%s); log: %s", status_name(status), args, LOG_LAST);
    if (exp == EXP_ERR) n_illegal_err++;
    if (exp == EXP_OK) n_legal_ok++;
    if (LOG_BAD_ENV) violation("the log callback was given another instance's environment");
    logged_expected = in && in->has_logger && in->logging;
    if (V == 3 && in && !in->logging && LOG_COUNT)
        violation("the log callback was called although logging is off: %s", LOG_LAST);
    if (status == 3 && logged_expected && !LOG_NAMED)
        violation("Error without a log message naming the function (log: %s)", LOG_COUNT ? LOG_LAST : "none");
    if (in && status == 3) in->st = S_ERR;
}

/* A call of fn, a function of the instance alone, on `in`, checked: the answer args_exp where
 * the state allows the call, Error elsewhere (args: for the trace); its status. */
static int plain(Inst *in, const char *fn, int args_exp, const char *args) {
    int st;
    begin(fn, in);
    st = call_alone(fn, H(in));
    end();
    check(in, STATE_EXP(in, fn, args_exp), st, args);
    return st;
}

/* ------------------------------------------------------------------ variables */
static int load_vars(const char *path) {
    FILE *f = fopen(path, "r");
    char line[512];
    if (!f) return 1;
    while (fgets(line, sizeof line, f) && NVARS < MAXVARS) {
        Var *v = &VARS[NVARS];
        char start[64];
        if (sscanf(line, "%u %c %c %c %c %63s %c", &v->vr, &v->type, &v->caus, &v->var, &v->init, start, &v->flag) != 7)
            continue;
        v->start = start[0] == '-' && !start[1] ? 0.0 : strtod(start, NULL);
        if (v->flag == 'S') NX++;
        NVARS++;
    }
    fclose(f);
    return NVARS == 0;
}

static const Var *var_of(unsigned vr) {
    for (int i = 0; i < NVARS; i++)
        if (VARS[i].vr == vr) return &VARS[i];
    return NULL;
}

/* A variable of type t (NULL if none). */
static const Var *some_var(Rng *r, char t) {
    int n = 0, k;
    for (int i = 0; i < NVARS; i++) n += VARS[i].type == t;
    if (!n) return NULL;
    k = pick(r, n);
    for (int i = 0; i < NVARS; i++)
        if (VARS[i].type == t && k-- == 0) return &VARS[i];
    return NULL;
}

/* A value reference no variable has. */
static unsigned unknown_vr(Rng *r) {
    unsigned vr;
    if (chance(r, 0.7)) vr = HOSTILE_VRS[pick(r, (int)(sizeof HOSTILE_VRS / sizeof HOSTILE_VRS[0]))];
    else vr = (unsigned)NVARS + 1000u + (unsigned)pick(r, 100000);
    return var_of(vr) ? 0xFFFFFFFFu : vr;
}

/* The standard's rule for setting variable v in state st: EXP_OK, EXP_ERR, or EXP_ANY where
 * the standard leaves it open (FMI 2.0 and 3.0 differ, or the FMU may refuse a value). */
static int set_rule(const Var *v, int st) {
    int in = v->caus == 'i', exact = v->init == 'e' || v->init == 'a';
    if (v->caus == 't' || v->var == 'c' || v->init == 'c' || v->caus == 'c') return EXP_ERR;
    switch (st) {
    case S_INST: return exact ? EXP_OK : (in ? EXP_ANY : EXP_ERR);
    case S_INIT: return exact || in ? EXP_OK : EXP_ERR;
    case S_STEP: case S_EVENT: case S_ACT:
        if (in || (v->caus == 'p' && v->var == 't')) return EXP_OK;
        return EXP_ERR;
    case S_CONT:
        if (in && v->var == 'n' && v->type == 'R') return EXP_OK;
        if (v->flag == 'S') return V == 2 ? EXP_OK : EXP_ANY;   /* a state: FMI 2.0.1 note 5 allows it */
        return EXP_ERR;
    default: return EXP_ERR;
    }
}

/* ------------------------------------------------------------------ the clock (clocked FMUs) */
/* Where the instance's next activation t0 + n T lies against t: 0 after it, 1 at it (within
 * 1e-6 T), 2 before it (missed). */
static int clock_due(const Inst *in, double t) {
    double q = (t - in->clk.t0) / INTERVAL;
    if (fabs(q - (double)in->clk.n) <= 1e-6) return 1;
    return (double)in->clk.n < q ? 2 : 0;
}

/* The clock's rule for getting (set = 0) or setting a clocked variable in the instance's
 * state (the state table decides the rest); EXP_ANY once the instance holds values the model
 * cannot follow (a crafted FMU state). */
static int clock_access(const Inst *in, int set) {
    int ok;
    switch (in->st) {
    case S_EVENT: ok = in->clk.active; break;
    case S_STEP: ok = 0; break;
    case S_ACT: ok = set || in->clk.fresh; break;
    default: return EXP_OK;
    }
    if (in->dirty) return EXP_ANY;
    return ok ? EXP_OK : EXP_ERR;
}

/* EXP_OK if the clock allows the call (legal), else EXP_ERR; EXP_ANY for a dirty instance. */
static int clock_exp(const Inst *in, int legal) { return in->dirty ? EXP_ANY : legal ? EXP_OK : EXP_ERR; }

static void clock_reset(Inst *in) { memset(&in->clk, 0, sizeof in->clk); in->clk.t0 = in->time; }

/* ------------------------------------------------------------------ FMU states held by the driver */
static StateRec *state_rec(void *h, int owner) {
    for (int i = 0; i < NSTATES_HELD; i++)
        if (STATES[i].alive && STATES[i].h == h && STATES[i].owner == owner) return &STATES[i];
    return NULL;
}

static void state_forget_dead(void) {
    int j = 0;
    for (int i = 0; i < NSTATES_HELD; i++)
        if (STATES[i].alive || i >= NSTATES_HELD - 16) STATES[j++] = STATES[i];
    NSTATES_HELD = j;
}

static void state_add(void *h, const Inst *in) {
    StateRec *r = state_rec(h, in->id);
    if (!r) {
        for (int i = 0; i < NSTATES_HELD; i++)      /* a freed record at the same address is gone */
            if (STATES[i].h == h && STATES[i].owner == in->id) STATES[i].alive = 0;
        if (NSTATES_HELD == MAXSTATES) state_forget_dead();
        if (NSTATES_HELD == MAXSTATES) {              /* all alive: not held (the FMU frees it at FreeInstance) */
            for (int i = 0; i < NSTATES_HELD; i++)    /* and no freed record may claim its address */
                if (STATES[i].h == h) STATES[i].h = NULL;
            return;
        }
        r = &STATES[NSTATES_HELD++];
    }
    r->h = h; r->owner = in->id; r->alive = 1; r->st = in->st; r->time = in->time; r->dirty = in->dirty;
    r->clk = in->clk;
}

/* A state handle to pass: one of this instance's (alive, or freed), another instance's, or NULL. */
static void *some_state(Rng *r, const Inst *in, int *legal) {
    static int own[MAXSTATES];
    int n = 0;
    for (int i = 0; i < NSTATES_HELD; i++)
        if (STATES[i].alive && STATES[i].owner == in->id) own[n++] = i;
    if (n && chance(r, 0.8)) { *legal = 1; return STATES[own[pick(r, n)]].h; }
    *legal = 0;
    if (NSTATES_HELD && chance(r, 0.8)) {
        StateRec *s = &STATES[pick(r, NSTATES_HELD)];
        *legal = state_rec(s->h, in->id) != NULL;    /* the same address may be alive again here */
        return s->h;
    }
    return NULL;
}

static void states_of_instance_dead(int id) {
    for (int i = 0; i < NSTATES_HELD; i++)
        if (STATES[i].owner == id) STATES[i].alive = 0;
}

/* ------------------------------------------------------------------ instances */
static Inst *free_slot(void) {
    for (int i = 0; i < MAXINST; i++)
        if (!INST[i].h) return &INST[i];
    return NULL;
}

static int live_count(void) {
    int n = 0;
    for (int i = 0; i < MAXINST; i++) n += INST[i].h != NULL;
    return n;
}

static Inst *some_inst(Rng *r) {
    int n = live_count(), k;
    if (!n) return NULL;
    k = pick(r, n);
    for (int i = 0; i < MAXINST; i++)
        if (INST[i].h && k-- == 0) return &INST[i];
    return NULL;
}

static fmi2CallbackFunctions CB2_PLAIN = {logger2, calloc, free, NULL, NULL};

/* Instantiate into a free slot (hostile arguments with probability p_bad). */
static void op_instantiate(Rng *r, double p_bad) {
    Inst *in = free_slot(), tmp;
    int bad = chance(r, p_bad), what = pick(r, 9), exp = EXP_OK, expect_msg;
    int variant = 0;     /* FMI 2.0: 1 an invalid fmi2Type; FMI 3.0: 1 eventModeUsed, 2 required
                            intermediate variables, 3 Scheduled Execution */
    const char *token = TOKEN, *name;
    char args[200];
    void *h;
    if (!in) return;
    memset(&tmp, 0, sizeof tmp);
    tmp.id = NEXT_ID++;
    snprintf(tmp.name, sizeof tmp.name, "fuzz%d", tmp.id);
    name = tmp.name;
    tmp.cs = HAS_ME ? chance(r, 0.5) : 1;
    if (CLOCKED && !bad && chance(r, 0.35)) variant = 3;  /* Scheduled Execution: legal here */
    tmp.logging = chance(r, 0.7);
    tmp.has_logger = !chance(r, 0.1);
    if (bad) {
        exp = EXP_ERR;
        switch (what) {
        case 0: token = "{00000000-0000-0000-0000-000000000000}"; break;
        case 1: token = NULL; break;
        case 2: name = NULL; break;
        case 3: name = " "; break;
        case 4: if (HAS_ME) exp = EXP_OK; else tmp.cs = 0; break;    /* Model Exchange on a CS-only FMU */
        case 5: variant = 1; break;
        case 6: if (V == 3) variant = 2; else exp = EXP_OK; break;
        case 7: if (V == 3) variant = 3; else { tmp.flaky = 1; exp = EXP_ANY; } break;   /* CLOCKED: legal */
        default: if (V == 2) { tmp.flaky = 1; exp = EXP_ANY; } else exp = EXP_OK;
        }
    }
    expect_msg = tmp.has_logger && (V == 2 || tmp.logging);
    snprintf(args, sizeof args, "%s logging=%d logger=%d token=%s name=%s variant=%d flaky=%d",
             tmp.cs ? "CS" : "ME", tmp.logging, tmp.has_logger, token ? (token == TOKEN ? "ok" : "wrong") : "NULL",
             name ? name : "NULL", variant, tmp.flaky);
    if (V == 2) {
        fmi2CallbackFunctions cb = CB2_PLAIN;
        fmi2Type type = variant ? (fmi2Type)7 : tmp.cs ? fmi2CoSimulation : fmi2ModelExchange;
        if (!tmp.has_logger) cb.logger = NULL;
        if (tmp.flaky) cb.allocateMemory = flaky_alloc;
        cb.componentEnvironment = in;
        begin("fmi2Instantiate", in);
        h = F2(fmi2Instantiate)(name, type, token, "file:///tmp/", &cb, fmi2False, tmp.logging ? fmi2True : fmi2False);
        end();
    } else {
        fmi3LogMessageCallback log = tmp.has_logger ? logger3 : NULL;
        if (CLOCKED && variant == 3 && what == 7) exp = EXP_OK;
        if (variant == 3) {
            tmp.cs = 2;
            begin("fmi3InstantiateScheduledExecution", in);
            h = F3(fmi3InstantiateScheduledExecution)(name, token, NULL, fmi3False, tmp.logging, in, log, NULL, NULL, NULL);
        } else if (!tmp.cs && !variant) {
            begin("fmi3InstantiateModelExchange", in);
            h = F3(fmi3InstantiateModelExchange)(name, token, NULL, fmi3False, tmp.logging, in, log);
        } else {
            fmi3ValueReference req[1] = {VARS[0].vr};
            tmp.cs = 1;
            begin("fmi3InstantiateCoSimulation", in);
            /* eventModeUsed: required by a clocked FMU, refused by the others (variant 1: the wrong one) */
            h = F3(fmi3InstantiateCoSimulation)(name, token, NULL, fmi3False, tmp.logging,
                                                CLOCKED ? variant != 1 : variant == 1, fmi3False,
                                                variant == 2 ? req : NULL, variant == 2 ? 1 : 0, in, log, NULL);
        }
        end();
    }
    trace("%s %s -> %s (expected %s)%s%s", CUR_FN, args, h ? "instance" : "NULL", EXP_NAMES[exp],
          LOG_COUNT ? " log: " : "", LOG_COUNT ? LOG_LAST : "");
    if (exp == EXP_ERR) n_illegal++; else if (exp == EXP_OK) n_legal++; else n_any++;
    if (exp == EXP_ERR && h) violation("a refused instantiation returned an instance (%s)", args);
    if (exp == EXP_OK && !h) violation("a legal instantiation returned NULL (%s): %s", args, LOG_LAST);
    if (exp == EXP_ERR) n_illegal_err++;
    if (exp == EXP_OK) n_legal_ok++;
    if (LOG_BAD_ENV) violation("the log callback was given another environment");
    if (V == 3 && !tmp.logging && LOG_COUNT) violation("logging is off, yet the log callback was called: %s", LOG_LAST);
    if (!h && expect_msg && !LOG_NAMED)
        violation("a refused instantiation without a log message naming the function (log: %s)", LOG_COUNT ? LOG_LAST : "none");
    if (!h) return;
    n_inst++;
    if (V == 2) tmp.logging = 1;      /* FMI 2.0: errors are reported whatever loggingOn */
    tmp.h = h;
    tmp.st = S_INST;
    tmp.time = 0;
    *in = tmp;
}

static void op_free(Inst *in) {
    char args[40];
    snprintf(args, sizeof args, "instance %d", in->id);
    if (V == 2) { begin("fmi2FreeInstance", in); F2(fmi2FreeInstance)(in->h); }
    else { begin("fmi3FreeInstance", in); F3(fmi3FreeInstance)(in->h); }
    end();
    trace("%s %s", CUR_FN, args);
    if (V == 3 && !in->logging && LOG_COUNT) violation("logging is off, yet the log callback was called: %s", LOG_LAST);
    states_of_instance_dead(in->id);
    in->h = NULL;
}

/* ------------------------------------------------------------------ the calls
 * Each op_X(r, in, bad) makes one call on instance `in` (a legal one when bad = 0: legal
 * arguments, though the state may be wrong: the model decides) and checks the answer. */
typedef void (*Op)(Rng *, Inst *, int);

static void op_set_debug_logging(Rng *r, Inst *in, int bad) {
    const char *fn = V == 2 ? "fmi2SetDebugLogging" : "fmi3SetDebugLogging";
    const char *cats[2] = {"logStatusError", "logAll"};
    const char *badcats[1] = {"noSuchCategory"};
    const char *nullcat[1] = {NULL};
    const char **c = NULL;
    size_t n = 0;
    int on = chance(r, 0.7), exp = EXP_OK, k = pick(r, 4), st;
    char args[80];
    if (bad) {
        exp = EXP_ERR;
        if (k == 0) { n = 1; c = NULL; } else if (k == 1) { n = 1; c = badcats; } else { n = 1; c = nullcat; }
    } else if (k == 1) { n = 1; c = cats; } else if (k == 2) { n = 1; c = cats + 1; } else if (k == 3) { n = 2; c = cats; }
    exp = STATE_EXP(in, fn, exp);
    snprintf(args, sizeof args, "on=%d n=%zu cats=%s", on, n, c ? (c == badcats ? "unknown" : c[0] ? c[0] : "{NULL}") : "NULL");
    begin(fn, in);
    st = V == 2 ? (int)F2(fmi2SetDebugLogging)(H(in), on, n, c) : (int)F3(fmi3SetDebugLogging)(H(in), on, n, c);
    end();
    check(in, exp, st, args);
    if (st == 0 && V == 3) in->logging = on;   /* each category enables the error messages */
}

static void op_setup_experiment(Rng *r, Inst *in, int bad) {
    const char *fn = V == 2 ? "fmi2SetupExperiment" : "fmi3EnterInitializationMode";
    double start = (double)pick(r, 5) - 2.0, stop = start + 10, tol = 1e-6;
    int tolDef = chance(r, 0.3), stopDef = chance(r, 0.5), exp = EXP_OK, st;
    char args[120];
    if (bad) {
        int k = pick(r, 6);
        if (k == 0) { start = NAN; exp = EXP_ERR; }
        else if (k == 1) { start = chance(r, 0.5) ? INFINITY : -INFINITY; exp = EXP_ERR; }
        else if (k == 2) { start = chance(r, 0.5) ? 1e300 : -1e300; exp = EXP_ANY; stopDef = 0; }
        else if (k == 3) { stopDef = 1; stop = start - 1; exp = EXP_ANY; }
        else if (k == 4) { tolDef = 1; tol = chance(r, 0.5) ? NAN : -1; exp = EXP_ANY; }
        else { start = 4.9406564584124654e-324; exp = EXP_OK; }
    }
    exp = STATE_EXP(in, fn, exp);
    snprintf(args, sizeof args, "tolDef=%d tol=%g start=%g stopDef=%d stop=%g", tolDef, tol, start, stopDef, stop);
    begin(fn, in);
    st = V == 2 ? (int)F2(fmi2SetupExperiment)(H(in), tolDef, tol, start, stopDef, stop)
                : (int)F3(fmi3EnterInitializationMode)(H(in), tolDef, tol, start, stopDef, stop);
    end();
    check(in, exp, st, args);
    if (st == 0) {
        if (exp == EXP_ANY) in->dirty = 1;
        in->time = start;
        if (V == 3) in->st = S_INIT;
    }
}

static void op_enter_init(Rng *r, Inst *in, int bad) {
    if (V == 3) { op_setup_experiment(r, in, bad); return; }
    if (plain(in, "fmi2EnterInitializationMode", EXP_OK, "") == 0) in->st = S_INIT;
}

static void op_exit_init(Rng *r, Inst *in, int bad) {
    (void)r; (void)bad;
    if (plain(in, VFN(ExitInitializationMode), EXP_OK, "") == 0) {
        in->st = in->cs == 2 ? S_ACT : in->cs && !CLOCKED ? S_STEP : S_EVENT;
        clock_reset(in);
    }
}

static void op_terminate(Rng *r, Inst *in, int bad) {
    (void)r; (void)bad;
    if (plain(in, VFN(Terminate), EXP_OK, "") == 0) in->st = S_TERM;
}

static void op_reset(Rng *r, Inst *in, int bad) {
    (void)r; (void)bad;
    if (plain(in, VFN(Reset), EXP_OK, "") == 0) { in->st = S_INST; in->dirty = 0; in->time = 0; clock_reset(in); }
}

/* Getters and setters. t: the variable type the function takes (R, I, L, B; 0: a type this
 * FMU has no variable of). */
static void op_values(Rng *r, Inst *in, int bad, int set, char t, const char *fn) {
    unsigned vr[4];
    double dv[4];
    long long lv[4];
    int iv[4];
    fmi2Boolean bv2[4];
    fmi3Boolean bv3[4];
    size_t n = (size_t)pick(r, 4), nv;
    int exp = EXP_OK, st = 0, hostile_value = 0, k = bad ? pick(r, 5) : -1;
    const void *vrp = vr, *vp = NULL;
    char args[160];
    for (size_t i = 0; i < n; i++) {
        const Var *v = t ? some_var(r, t) : NULL;
        if (!v) { n = i; break; }
        vr[i] = v->vr;
        if (set) {
            int e = set_rule(v, in->st);
            if (e == EXP_ERR) exp = EXP_ERR;
            else if (e == EXP_ANY && exp == EXP_OK) exp = EXP_ANY;
        }
        if (CLOCKED && v->flag == 'K') {
            int e = clock_access(in, set);
            if (e == EXP_ERR) exp = EXP_ERR;
            else if (e == EXP_ANY && exp == EXP_OK) exp = EXP_ANY;
        }
        dv[i] = v->caus == 'i' ? uniform(r, -0.1, 0.1) : v->start;
        lv[i] = (long long)v->start;
        iv[i] = (int)v->start;
        bv2[i] = bv3[i] = chance(r, 0.5) ? 1 : v->start != 0;
    }
    nv = n;
    if (k == 0 && n) { vr[pick(r, (int)n)] = unknown_vr(r); exp = EXP_ERR; }
    else if (k == 1 && n) { vrp = NULL; exp = EXP_ERR; }
    else if (k == 2 && n) { vp = (const void *)1; exp = EXP_ERR; }      /* NULL values, below */
    else if (k == 3 && V == 3) { nv = n + 1 + (size_t)pick(r, 3); exp = EXP_ERR; }
    else if (k == 4 && n && set) {
        int i = pick(r, (int)n);
        hostile_value = 1;
        dv[i] = HOSTILE_REALS[pick(r, (int)(sizeof HOSTILE_REALS / sizeof HOSTILE_REALS[0]))];
        lv[i] = chance(r, 0.5) ? (long long)0x7FFFFFFF : chance(r, 0.5) ? -1 : (long long)0x80000000 * -1;
        iv[i] = chance(r, 0.5) ? 0x7FFFFFFF : chance(r, 0.5) ? -1 : (int)0x80000000;
        bv2[i] = 7;
        if (exp == EXP_OK) exp = EXP_ANY;
    }
    if (!t && n == 0 && bad && k == 0) { n = 1; nv = 1; vr[0] = unknown_vr(r); exp = EXP_ERR; }
    exp = STATE_EXP(in, fn, exp);
    snprintf(args, sizeof args, "n=%zu nv=%zu vr0=%u%s%s%s", n, nv, n ? vr[0] : 0u, vrp ? "" : " vr=NULL",
             vp == (const void *)1 ? " values=NULL" : "", hostile_value ? " hostile value" : "");
    {
        int null_values = vp == (const void *)1;
        double *D = null_values ? NULL : dv;
        void *buf = NULL;
        begin(fn, in);
        if (V == 2) {
            const fmi2ValueReference *VR = (const fmi2ValueReference *)vrp;
            if (t == 'R') st = set ? (int)F2(fmi2SetReal)(H(in), VR, n, D) : (int)F2(fmi2GetReal)(H(in), VR, n, D);
            else if (t == 'I' || t == 'L') {
                int *I = null_values ? NULL : iv;
                st = set ? (int)F2(fmi2SetInteger)(H(in), VR, n, I) : (int)F2(fmi2GetInteger)(H(in), VR, n, I);
            } else if (t == 'B') {
                fmi2Boolean *Bv = null_values ? NULL : bv2;
                st = set ? (int)F2(fmi2SetBoolean)(H(in), VR, n, Bv) : (int)F2(fmi2GetBoolean)(H(in), VR, n, Bv);
            } else {
                fmi2String sv[4] = {"a", "b", "c", "d"};
                st = set ? (int)F2(fmi2SetString)(H(in), VR, n, null_values ? NULL : sv)
                         : (int)F2(fmi2GetString)(H(in), VR, n, null_values ? NULL : sv);
            }
        } else {
            const fmi3ValueReference *VR = (const fmi3ValueReference *)vrp;
            if (nv > 4) buf = calloc(nv, 8);
            if (t == 'R') {
                double *Dv = buf ? (double *)buf : D;
                st = set ? (int)F3(fmi3SetFloat64)(H(in), VR, n, Dv, nv) : (int)F3(fmi3GetFloat64)(H(in), VR, n, Dv, nv);
            } else if (t == 'I') {
                fmi3Int32 *I = buf ? (fmi3Int32 *)buf : null_values ? NULL : (fmi3Int32 *)iv;
                st = set ? (int)F3(fmi3SetInt32)(H(in), VR, n, I, nv) : (int)F3(fmi3GetInt32)(H(in), VR, n, I, nv);
            } else if (t == 'L') {
                fmi3Int64 *L = buf ? (fmi3Int64 *)buf : null_values ? NULL : (fmi3Int64 *)lv;
                st = set ? (int)F3(fmi3SetInt64)(H(in), VR, n, L, nv) : (int)F3(fmi3GetInt64)(H(in), VR, n, L, nv);
            } else if (t == 'B') {
                fmi3Boolean *Bv = buf ? (fmi3Boolean *)buf : null_values ? NULL : bv3;
                st = set ? (int)F3(fmi3SetBoolean)(H(in), VR, n, Bv, nv) : (int)F3(fmi3GetBoolean)(H(in), VR, n, Bv, nv);
            } else if (!strcmp(fn, "fmi3GetFloat32") || !strcmp(fn, "fmi3SetFloat32")) {
                float f[8] = {0};
                st = set ? (int)F3(fmi3SetFloat32)(H(in), VR, n, null_values ? NULL : f, nv)
                         : (int)F3(fmi3GetFloat32)(H(in), VR, n, null_values ? NULL : f, nv);
            } else if (!strcmp(fn, "fmi3GetUInt8") || !strcmp(fn, "fmi3SetUInt8")) {
                fmi3UInt8 u8[8] = {0};
                st = set ? (int)F3(fmi3SetUInt8)(H(in), VR, n, null_values ? NULL : u8, nv)
                         : (int)F3(fmi3GetUInt8)(H(in), VR, n, null_values ? NULL : u8, nv);
            } else if (!strcmp(fn, "fmi3GetBinary") || !strcmp(fn, "fmi3SetBinary")) {
                size_t sizes[8] = {0};
                fmi3Binary bins[8] = {0};
                if (set) st = (int)F3(fmi3SetBinary)(H(in), VR, n, sizes, null_values ? NULL : (const fmi3Binary *)bins, nv);
                else st = (int)F3(fmi3GetBinary)(H(in), VR, n, sizes, null_values ? NULL : bins, nv);
            } else {
                fmi3String sv[8] = {"a", "b", "c", "d", "e", "f", "g", "h"};
                st = set ? (int)F3(fmi3SetString)(H(in), VR, n, null_values ? NULL : sv, nv)
                         : (int)F3(fmi3GetString)(H(in), VR, n, null_values ? NULL : sv, nv);
            }
        }
        end();
        free(buf);
    }
    check(in, exp, st, args);
    if (st == 0 && exp == EXP_ANY) in->dirty = 1;
    if (st == 0 && set && n && in->st == S_ACT) in->clk.fresh = 0;     /* no get after a set */
}

static char value_type(Rng *r, const char **get, const char **set) {
    static const char types[] = "RILB";
    char t = types[pick(r, 4)];
    if (V == 2) {
        if (chance(r, 0.1)) { *get = "fmi2GetString"; *set = "fmi2SetString"; return 0; }
        if (t == 'L') t = 'I';
        *get = t == 'R' ? "fmi2GetReal" : t == 'B' ? "fmi2GetBoolean" : "fmi2GetInteger";
        *set = t == 'R' ? "fmi2SetReal" : t == 'B' ? "fmi2SetBoolean" : "fmi2SetInteger";
        return t;
    }
    if (chance(r, 0.15)) {
        static const char *g[] = {"fmi3GetString", "fmi3GetFloat32", "fmi3GetUInt8", "fmi3GetBinary"};
        static const char *s[] = {"fmi3SetString", "fmi3SetFloat32", "fmi3SetUInt8", "fmi3SetBinary"};
        int k = pick(r, 4);
        *get = g[k]; *set = s[k];
        return 0;
    }
    *get = t == 'R' ? "fmi3GetFloat64" : t == 'I' ? "fmi3GetInt32" : t == 'L' ? "fmi3GetInt64" : "fmi3GetBoolean";
    *set = t == 'R' ? "fmi3SetFloat64" : t == 'I' ? "fmi3SetInt32" : t == 'L' ? "fmi3SetInt64" : "fmi3SetBoolean";
    return t;
}

static void op_get(Rng *r, Inst *in, int bad) {
    const char *g, *s;
    char t = value_type(r, &g, &s);
    op_values(r, in, bad, 0, t, g);
}

static void op_set(Rng *r, Inst *in, int bad) {
    const char *g, *s;
    char t = value_type(r, &g, &s);
    op_values(r, in, bad, 1, t, s);
}

/* ------------------------------------------------------------------ FMU states */
static void op_get_state(Rng *r, Inst *in, int bad) {
    const char *fn = V == 2 ? "fmi2GetFMUstate" : "fmi3GetFMUState";
    void *s = NULL, **sp = &s;
    int exp = EXP_OK, st, legal = 1;
    char args[60] = "new";
    if (chance(r, 0.3)) { s = some_state(r, in, &legal); if (!legal && s) exp = EXP_ERR; snprintf(args, sizeof args, "overwrite %p", s); }
    if (bad) { sp = NULL; exp = EXP_ERR; snprintf(args, sizeof args, "FMUstate pointer NULL"); }
    if (in->flaky && exp == EXP_OK) exp = EXP_ANY;
    exp = STATE_EXP(in, fn, exp);
    begin(fn, in);
    st = V == 2 ? (int)F2(fmi2GetFMUstate)(H(in), (fmi2FMUstate *)sp) : (int)F3(fmi3GetFMUState)(H(in), (fmi3FMUState *)sp);
    end();
    check(in, exp, st, args);
    if (st == 0 && s) state_add(s, in);
}

static void op_set_state(Rng *r, Inst *in, int bad) {
    const char *fn = V == 2 ? "fmi2SetFMUstate" : "fmi3SetFMUState";
    int legal, exp, st;
    void *s = some_state(r, in, &legal);
    StateRec *rec = s ? state_rec(s, in->id) : NULL;
    char args[60];
    (void)bad;
    exp = s && legal ? EXP_OK : EXP_ERR;
    if (exp == EXP_OK && rec && rec->dirty) exp = EXP_ANY;
    exp = STATE_EXP(in, fn, exp);
    snprintf(args, sizeof args, "%p (%s)", s, s ? (legal ? "own" : "freed or foreign") : "NULL");
    begin(fn, in);
    st = V == 2 ? (int)F2(fmi2SetFMUstate)(H(in), s) : (int)F3(fmi3SetFMUState)(H(in), s);
    end();
    if (exp == EXP_OK && in->dirty) exp = EXP_OK;    /* restoring a clean state is legal whatever came before */
    {
        int d = in->dirty;
        in->dirty = 0;
        check(in, exp, st, args);
        in->dirty = d;
    }
    if (st == 0 && rec) { in->st = rec->st; in->time = rec->time; in->dirty = rec->dirty; in->clk = rec->clk; }
}

static void op_free_state(Rng *r, Inst *in, int bad) {
    const char *fn = V == 2 ? "fmi2FreeFMUstate" : "fmi3FreeFMUState";
    int legal, exp, st;
    void *s = some_state(r, in, &legal), **sp = &s;
    StateRec *rec = s ? state_rec(s, in->id) : NULL;
    char args[60];
    exp = !s || legal ? EXP_OK : EXP_ERR;
    if (bad && chance(r, 0.5)) { sp = NULL; exp = EXP_OK; }      /* NULL: nothing to free */
    exp = STATE_EXP(in, fn, exp);
    snprintf(args, sizeof args, "%p (%s)", sp ? s : NULL, !sp || !s ? "NULL" : legal ? "own" : "freed or foreign");
    begin(fn, in);
    st = V == 2 ? (int)F2(fmi2FreeFMUstate)(H(in), (fmi2FMUstate *)sp) : (int)F3(fmi3FreeFMUState)(H(in), (fmi3FMUState *)sp);
    end();
    check(in, exp, st, args);
    if (st == 0 && sp && rec) {
        rec->alive = 0;
        if (s) violation("the freed state pointer was not set to NULL");
    }
}

static void op_serialize(Rng *r, Inst *in, int bad) {
    const char *fs = V == 2 ? "fmi2SerializedFMUstateSize" : "fmi3SerializedFMUStateSize";
    const char *fn = V == 2 ? "fmi2SerializeFMUstate" : "fmi3SerializeFMUState";
    int legal, exp, st, k = bad ? pick(r, 3) : -1;
    void *s = some_state(r, in, &legal);
    StateRec *rec = s ? state_rec(s, in->id) : NULL;
    size_t size = 0, *sizep = &size;
    unsigned char *buf;
    char args[80];
    exp = s && legal ? EXP_OK : EXP_ERR;
    if (k == 0) { sizep = NULL; exp = EXP_ERR; }
    snprintf(args, sizeof args, "%p%s", s, sizep ? "" : " size=NULL");
    exp = STATE_EXP(in, fs, exp);
    begin(fs, in);
    st = V == 2 ? (int)F2(fmi2SerializedFMUstateSize)(H(in), s, sizep) : (int)F3(fmi3SerializedFMUStateSize)(H(in), s, sizep);
    end();
    check(in, exp, st, args);
    if (st != 0 || !rec) return;
    if (size == 0 || size > (1u << 26)) violation("serialised size %zu", size);
    buf = (unsigned char *)malloc(size);
    exp = EXP_OK;
    {
        size_t give = size;
        unsigned char *out = buf;
        if (k == 1) { give = size - 1 - (size_t)pick(r, (int)(size < 8 ? size - 1 : 8)); exp = EXP_ERR; }
        if (k == 2) { out = NULL; exp = EXP_ERR; }
        snprintf(args, sizeof args, "%p size=%zu%s", s, give, out ? "" : " buffer=NULL");
        exp = STATE_EXP(in, fn, exp);
        begin(fn, in);
        st = V == 2 ? (int)F2(fmi2SerializeFMUstate)(H(in), s, (fmi2Byte *)out, give)
                    : (int)F3(fmi3SerializeFMUState)(H(in), s, out, give);
        end();
        check(in, exp, st, args);
    }
    if (st == 0) {
        Blob *b;
        if (NBLOBS == MAXBLOBS) { free(BLOBS[0].bytes); memmove(BLOBS, BLOBS + 1, sizeof(Blob) * (MAXBLOBS - 1)); NBLOBS--; }
        b = &BLOBS[NBLOBS++];
        b->bytes = buf; b->size = size; b->cs = in->cs; b->st = rec->st; b->time = rec->time; b->dirty = rec->dirty;
        b->clk = rec->clk;
    } else {
        free(buf);
    }
}

/* SavedState (wrapper_common.h): magic, size, mode, cosim (4 bytes each), then the FNV-1a
 * 64-bit checksum of the whole block (taken with the checksum zero), then CoreData. */
#define CRAFT_HASH_AT 16
#define CRAFT_OFFSET 24
static void craft_hash(unsigned char *b, size_t size) {
    uint64_t h = 0xcbf29ce484222325ull;
    memset(b + CRAFT_HASH_AT, 0, 8);
    for (size_t i = 0; i < size; i++) h = (h ^ b[i]) * 0x100000001b3ull;
    memcpy(b + CRAFT_HASH_AT, &h, 8);
}

static void op_deserialize(Rng *r, Inst *in, int bad) {
    const char *fn = V == 2 ? "fmi2DeSerializeFMUstate" : "fmi3DeserializeFMUState";
    Blob *b = NBLOBS ? &BLOBS[pick(r, NBLOBS)] : NULL;
    unsigned char *bytes, junk[64];
    size_t size;
    void *s = NULL, **sp = &s;
    int exp, st, k = bad ? pick(r, 7) : -1, legal = 1;
    char args[100];
    if (!b) { memset(junk, 0xA5, sizeof junk); bytes = junk; size = sizeof junk; exp = EXP_ERR; }
    else {
        bytes = (unsigned char *)malloc(b->size);
        memcpy(bytes, b->bytes, b->size);
        size = b->size;
        exp = b->cs == in->cs ? (b->dirty ? EXP_ANY : EXP_OK) : EXP_ERR;
    }
    if (k == 0 && b) { bytes[pick(r, (int)size)] ^= (unsigned char)(1 + pick(r, 255)); exp = EXP_ERR; }
    else if (k == 1) { size = size ? size - 1 : 0; exp = EXP_ERR; }
    else if (k == 2) { sp = NULL; exp = EXP_ERR; }
    else if (k == 3) { s = some_state(r, in, &legal); if (!legal && s) exp = EXP_ERR; }
    else if (k >= 5 && b && size > CRAFT_OFFSET + 8) {
        /* a crafted state: values of the core's data changed, the checksum made to match (the
         * layout of wrapper_common.h's SavedState): the FMU must check every value it uses */
        int m = 1 + pick(r, 4);
        for (int q = 0; q < m; q++) {
            size_t at = CRAFT_OFFSET + 8 * (size_t)pick(r, (int)((size - CRAFT_OFFSET) / 8));
            double hv = HOSTILE_REALS[pick(r, (int)(sizeof HOSTILE_REALS / sizeof HOSTILE_REALS[0]))];
            if (chance(r, 0.5)) memcpy(bytes + at, &hv, 8);
            else { uint64_t w = rnd(r); memcpy(bytes + at, &w, 8); }
        }
        craft_hash(bytes, size);
        exp = EXP_ANY;
    }
    snprintf(args, sizeof args, "%zu bytes%s%s%s%s", size, k == 0 ? " changed" : "", sp ? "" : " FMUstate pointer NULL",
             k == 3 ? " into a held state" : "", k >= 5 ? " crafted" : "");
    exp = STATE_EXP(in, fn, exp);
    begin(fn, in);
    st = V == 2 ? (int)F2(fmi2DeSerializeFMUstate)(H(in), (const fmi2Byte *)(k == 4 ? NULL : bytes), size, (fmi2FMUstate *)sp)
                : (int)F3(fmi3DeserializeFMUState)(H(in), k == 4 ? NULL : bytes, size, (fmi3FMUState *)sp);
    end();
    if (k == 4 && exp != EXP_ERR) exp = STATE_EXP(in, fn, EXP_ERR);
    if (in->flaky && exp == EXP_OK) exp = EXP_ANY;
    check(in, exp, st, args);
    if (st == 0 && s) {
        int keep = in->st;
        double t = in->time;
        int d = in->dirty;
        Clk c = in->clk;
        in->st = b ? b->st : keep; in->time = b ? b->time : t; in->dirty = b ? b->dirty || k >= 5 : 1;
        if (b) in->clk = b->clk;
        state_add(s, in);
        in->st = keep; in->time = t; in->dirty = d; in->clk = c;
    }
    if (bytes != junk) free(bytes);
}

/* ------------------------------------------------------------------ derivatives */
/* A Real variable of causality caus or with the flag (up to 50 tries); if none is found, its
 * value reference or 0, and *exp EXP_ANY. */
static unsigned some_real(Rng *r, char caus, char flag, int *exp) {
    int tries = 0;
    const Var *v;
    do v = some_var(r, 'R'); while (v && !(v->caus == caus || v->flag == flag) && ++tries < 50);
    if (!v || !(v->caus == caus || v->flag == flag)) *exp = EXP_ANY;
    return v ? v->vr : 0;
}

static void op_directional(Rng *r, Inst *in, int bad) {
    int adj = V == 3 && chance(r, 0.4);
    const char *fn = V == 2 ? "fmi2GetDirectionalDerivative" : adj ? "fmi3GetAdjointDerivative" : "fmi3GetDirectionalDerivative";
    unsigned unk[4], kn[4];
    double seed[4] = {1, 0.5, -1, 2}, sens[4];
    size_t nU = 1 + (size_t)pick(r, 3), nK = 1 + (size_t)pick(r, 3), nSeed, nSens;
    int exp = HAS_DD ? EXP_OK : EXP_ERR, st, k = bad ? pick(r, 4) : -1;
    const unsigned *U = unk, *K = kn;
    char args[100];
    for (size_t i = 0; i < nU; i++) unk[i] = some_real(r, 'o', 'D', &exp);     /* outputs, derivatives */
    for (size_t i = 0; i < nK; i++) kn[i] = some_real(r, 'i', 'S', &exp);      /* inputs, states */
    if (!HAS_DD) exp = EXP_ERR;
    if (k == 0) { unk[0] = unknown_vr(r); exp = EXP_ERR; }
    else if (k == 1) { U = NULL; exp = EXP_ERR; }
    else if (k == 2) { K = NULL; exp = EXP_ERR; }
    nSeed = adj ? nU : nK;
    nSens = adj ? nK : nU;
    if (k == 3 && V == 3) { nSeed += 1; exp = EXP_ERR; }
    exp = STATE_EXP(in, fn, exp);
    snprintf(args, sizeof args, "nU=%zu nK=%zu unk0=%u kn0=%u%s%s", nU, nK, unk[0], kn[0], U ? "" : " unknowns=NULL",
             K ? "" : " knowns=NULL");
    begin(fn, in);
    if (V == 2) st = (int)F2(fmi2GetDirectionalDerivative)(H(in), U, nU, K, nK, seed, sens);
    else if (adj) st = (int)F3(fmi3GetAdjointDerivative)(H(in), U, nU, K, nK, seed, nSeed, sens, nSens);
    else st = (int)F3(fmi3GetDirectionalDerivative)(H(in), U, nU, K, nK, seed, nSeed, sens, nSens);
    end();
    check(in, exp, st, args);
}

/* ------------------------------------------------------------------ Model Exchange */
static void op_enter_event(Rng *r, Inst *in, int bad);
static void op_update_discrete(Rng *r, Inst *in, int bad);

static void op_me_mode(Rng *r, Inst *in, int bad) {
    int k = pick(r, 4), st;
    const char *fn;
    char args[60] = "";
    fmi2EventInfo e;
    fmi2Boolean b2[2] = {0, 0};
    fmi3Boolean b[5] = {0};
    fmi3Float64 next = 0;
    if (CLOCKED && k < 2) { (k ? op_update_discrete : op_enter_event)(r, in, bad); return; }   /* the clock's rules */
    if (k == 0 || k == 2) {                                   /* Event Mode, Continuous-Time Mode */
        if (plain(in, k ? VFN(EnterContinuousTimeMode) : VFN(EnterEventMode), EXP_OK, args) == 0)
            in->st = k ? S_CONT : S_EVENT;
        return;
    }
    /* the end of an event (its discrete states) or of an integrator step: a NULL output when bad */
    fn = k == 1 ? (V == 2 ? "fmi2NewDiscreteStates" : "fmi3UpdateDiscreteStates") : VFN(CompletedIntegratorStep);
    snprintf(args, sizeof args, "%s", !bad ? "" : k == 1 ? (V == 2 ? "eventInfo=NULL" : "nextEventTime=NULL")
                                      : V == 2 ? "enterEventMode=NULL" : "terminateSimulation=NULL");
    begin(fn, in);
    if (V == 2 && k == 1) st = (int)F2(fmi2NewDiscreteStates)(H(in), bad ? NULL : &e);
    else if (V == 2) st = (int)F2(fmi2CompletedIntegratorStep)(H(in), fmi2True, bad ? NULL : &b2[0], &b2[1]);
    else if (k == 1) st = (int)F3(fmi3UpdateDiscreteStates)(H(in), &b[0], &b[1], &b[2], &b[3], &b[4], bad ? NULL : &next);
    else st = (int)F3(fmi3CompletedIntegratorStep)(H(in), fmi3True, &b[0], bad ? NULL : &b[1]);
    end();
    check(in, STATE_EXP(in, fn, bad ? EXP_ERR : EXP_OK), st, args);
    if (V == 2 && k == 1 && st == 0 && (e.newDiscreteStatesNeeded || e.terminateSimulation))
        violation("event info asks for more");
}

static void op_set_time(Rng *r, Inst *in, int bad) {
    const char *fn = V == 2 ? "fmi2SetTime" : "fmi3SetTime";
    double t = in->time + uniform(r, -0.01, 0.05);
    int exp = EXP_OK, st;
    char args[40];
    if (bad) {
        int k = pick(r, 3);
        t = k == 0 ? NAN : k == 1 ? INFINITY : 1e300;
        exp = k == 2 ? EXP_ANY : EXP_ERR;
    }
    exp = STATE_EXP(in, fn, exp);
    snprintf(args, sizeof args, "t=%g", t);
    begin(fn, in);
    st = V == 2 ? (int)F2(fmi2SetTime)(H(in), t) : (int)F3(fmi3SetTime)(H(in), t);
    end();
    check(in, exp, st, args);
    if (st == 0) { in->time = t; if (exp == EXP_ANY) in->dirty = 1; }
}

/* The functions on the continuous states: set, get, derivatives, nominals, event indicators. */
static void op_states(Rng *r, Inst *in, int bad) {
    static const char *F2N[] = {"fmi2SetContinuousStates", "fmi2GetContinuousStates", "fmi2GetDerivatives",
                                "fmi2GetNominalsOfContinuousStates", "fmi2GetEventIndicators"};
    static const char *F3N[] = {"fmi3SetContinuousStates", "fmi3GetContinuousStates",
                                "fmi3GetContinuousStateDerivatives", "fmi3GetNominalsOfContinuousStates",
                                "fmi3GetEventIndicators"};
    int k = pick(r, 5), exp = EXP_OK, st, b = bad ? pick(r, 3) : -1, hostile = 0;
    const char *fn = V == 2 ? F2N[k] : F3N[k];
    double x[64];
    double *X = x;
    size_t n = k == 4 ? 0 : (size_t)NX;
    char args[60];
    for (int i = 0; i < 64; i++) x[i] = uniform(r, -1, 1);
    if (b == 0) { n = n + 1 + (size_t)pick(r, 3); exp = EXP_ERR; }
    else if (b == 1 && n) { X = NULL; exp = EXP_ERR; }
    else if (b == 2 && k == 0 && n) { x[pick(r, (int)n)] = HOSTILE_REALS[pick(r, 5)]; exp = EXP_ANY; hostile = 1; }
    if (n > 64) n = 64;
    exp = STATE_EXP(in, fn, exp);
    snprintf(args, sizeof args, "n=%zu%s%s", n, X ? "" : " x=NULL", hostile ? " hostile value" : "");
    begin(fn, in);
    if (V == 2) {
        if (k == 0) st = (int)F2(fmi2SetContinuousStates)(H(in), X, n);
        else if (k == 1) st = (int)F2(fmi2GetContinuousStates)(H(in), X, n);
        else if (k == 2) st = (int)F2(fmi2GetDerivatives)(H(in), X, n);
        else if (k == 3) st = (int)F2(fmi2GetNominalsOfContinuousStates)(H(in), X, n);
        else st = (int)F2(fmi2GetEventIndicators)(H(in), X, n);
    } else {
        if (k == 0) st = (int)F3(fmi3SetContinuousStates)(H(in), X, n);
        else if (k == 1) st = (int)F3(fmi3GetContinuousStates)(H(in), X, n);
        else if (k == 2) st = (int)F3(fmi3GetContinuousStateDerivatives)(H(in), X, n);
        else if (k == 3) st = (int)F3(fmi3GetNominalsOfContinuousStates)(H(in), X, n);
        else st = (int)F3(fmi3GetEventIndicators)(H(in), X, n);
    }
    end();
    check(in, exp, st, args);
    if (st == 0 && hostile) in->dirty = 1;
}

static void op_number_of(Rng *r, Inst *in, int bad) {
    int k = pick(r, 2), st;
    const char *fn = k ? "fmi3GetNumberOfContinuousStates" : "fmi3GetNumberOfEventIndicators";
    size_t n = 99;
    if (V == 2) { op_states(r, in, bad); return; }
    begin(fn, in);
    st = k ? (int)F3(fmi3GetNumberOfContinuousStates)(H(in), bad ? NULL : &n)
           : (int)F3(fmi3GetNumberOfEventIndicators)(H(in), bad ? NULL : &n);
    end();
    check(in, STATE_EXP(in, fn, bad ? EXP_ERR : EXP_OK), st, bad ? "NULL" : "");
    if (st == 0 && n != (size_t)(k ? NX : 0)) violation("%zu returned", n);
}

/* ------------------------------------------------------------------ Co-Simulation */
static const double STEPS[] = {0.001, 0.0025, 0.005, 0.01, 0.01, 0.01, 0.015, 0.02, 0.05, 0.1};

static void op_do_step(Rng *r, Inst *in, int bad) {
    const char *fn = V == 2 ? "fmi2DoStep" : "fmi3DoStep";
    double t = in->time, h = STEPS[pick(r, (int)(sizeof STEPS / sizeof STEPS[0]))];
    int exp = EXP_OK, st, k = bad ? pick(r, 12) : -1;
    fmi3Boolean ev = 0, term = 0, early = 0;
    fmi3Float64 last = 0;
    char args[80];
    if (CLOCKED && in->st == S_STEP && chance(r, 0.6)) {        /* step to the next activation */
        double next = in->clk.t0 + (double)in->clk.n * INTERVAL;
        if (next > t) h = next - t;
    }
    if (k == 0) { t = NAN; exp = EXP_ERR; }
    else if (k == 1) { t = chance(r, 0.5) ? INFINITY : -INFINITY; exp = EXP_ERR; }
    else if (k == 2) { t = in->time + 1.0 + 1e-6 * fabs(in->time); exp = EXP_ERR; }   /* beyond the FMU's 1e-9 relative tolerance */
    else if (k == 3) { h = 0; exp = EXP_ERR; }
    else if (k == 4) { h = -0.01; exp = EXP_ERR; }
    else if (k == 5) { h = NAN; exp = EXP_ERR; }
    else if (k == 6) { h = INFINITY; exp = EXP_ERR; }
    else if (k == 7) { h = chance(r, 0.5) ? 1e300 : 1e6; exp = EXP_ANY; }
    else if (k == 8) { h = 4.9406564584124654e-324; exp = EXP_ANY; }
    else if (k == 9) { t = 1e300; exp = EXP_ERR; }
    else if (k == 10 && V == 3) { exp = EXP_ERR; }      /* NULL output pointers, below */
    else if (k == 11) { h = 1.7976931348623157e308; exp = EXP_ANY; }
    if (CLOCKED && exp == EXP_OK && (clock_due(in, t) != 0 || clock_due(in, t + h) == 2)) exp = clock_exp(in, 0);
    exp = STATE_EXP(in, fn, exp);
    if (t == 1e300 && in->time == 1e300) exp = EXP_ANY;
    snprintf(args, sizeof args, "t=%.17g h=%g%s", t, h, k == 10 && V == 3 ? " outputs=NULL" : "");
    begin(fn, in);
    if (V == 2) st = (int)F2(fmi2DoStep)(H(in), t, h, fmi2True);
    else st = (int)F3(fmi3DoStep)(H(in), t, h, fmi3True, k == 10 ? NULL : &ev, &term, &early, &last);
    end();
    check(in, exp, st, args);
    if (st == 0) {
        if (exp == EXP_ANY) in->dirty = 1;
        in->time = t + h;
        if (V == 3 && (ev || term || early || last != t + h)) violation("doStep outputs event=%d terminate=%d early=%d last=%g",
                                                                      ev, term, early, last);
    }
}

static void op_set_clock(Rng *r, Inst *in, int bad);
static void op_get_clock(Rng *r, Inst *in, int bad);
static void op_enter_step(Rng *r, Inst *in, int bad);
static void op_interval(Rng *r, Inst *in, int bad);
static void op_activate(Rng *r, Inst *in, int bad);

static void op_cs_misc(Rng *r, Inst *in, int bad) {
    int k = pick(r, 4), st, exp;
    if (CLOCKED && V == 3 && k > 0) {          /* the clock functions, with the clock's rules */
        static const Op ops[] = {op_enter_step, op_set_clock, op_get_clock, op_interval, op_activate};
        ops[pick(r, 5)](r, in, bad);
        return;
    }
    const char *fn;
    unsigned vr[1] = {VARS[0].vr};
    char args[40];
    snprintf(args, sizeof args, "n=%d", bad);
    if (V == 2) {
        if (k < 2) {                      /* the input and output derivatives: n of them when bad */
            fmi2Integer order[1] = {1};
            fmi2Real v[1] = {0};
            fn = k ? "fmi2GetRealOutputDerivatives" : "fmi2SetRealInputDerivatives";
            begin(fn, in);
            st = k ? (int)F2(fmi2GetRealOutputDerivatives)(H(in), vr, (size_t)bad, order, v)
                   : (int)F2(fmi2SetRealInputDerivatives)(H(in), vr, (size_t)bad, order, v);
            end();
            check(in, STATE_EXP(in, fn, bad ? EXP_ERR : EXP_OK), st, args);
        } else if (k == 2) {
            plain(in, "fmi2CancelStep", EXP_OK, "");
        } else {
            static const char *names[] = {"fmi2GetStatus", "fmi2GetRealStatus", "fmi2GetIntegerStatus",
                                          "fmi2GetBooleanStatus", "fmi2GetStringStatus"};
            int w = pick(r, 5);
            fmi2Status s2;
            fmi2Real rv;
            fmi2Integer iv;
            fmi2Boolean bv;
            fmi2String sv;
            fn = names[w];
            begin(fn, in);
            if (w == 0) st = (int)F2(fmi2GetStatus)(H(in), fmi2DoStepStatus, &s2);
            else if (w == 1) st = (int)F2(fmi2GetRealStatus)(H(in), fmi2LastSuccessfulTime, &rv);
            else if (w == 2) st = (int)F2(fmi2GetIntegerStatus)(H(in), fmi2DoStepStatus, &iv);
            else if (w == 3) st = (int)F2(fmi2GetBooleanStatus)(H(in), fmi2Terminated, &bv);
            else st = (int)F2(fmi2GetStringStatus)(H(in), fmi2PendingStatus, &sv);
            end();
            check(in, STATE_EXP(in, fn, EXP_OK), st, "");
        }
    } else {
        if (k == 0) {
            fmi3Int32 order[1] = {1};
            fmi3Float64 v[1] = {0};
            fn = "fmi3GetOutputDerivatives";
            begin(fn, in); st = (int)F3(fmi3GetOutputDerivatives)(H(in), vr, (size_t)bad, order, v, (size_t)bad); end();
            check(in, STATE_EXP(in, fn, bad ? EXP_ERR : EXP_OK), st, args);
        } else if (k == 1) {
            if (plain(in, "fmi3EnterStepMode", EXP_OK, "") == 0) in->st = S_STEP;
        } else if (k == 2) {
            fmi3Clock cl[1] = {0};
            fn = chance(r, 0.5) ? "fmi3GetClock" : "fmi3SetClock";
            exp = bad ? EXP_ERR : EXP_OK;
            begin(fn, in);
            st = fn[4] == 'G' ? (int)F3(fmi3GetClock)(H(in), vr, (size_t)bad, cl) : (int)F3(fmi3SetClock)(H(in), vr, (size_t)bad, cl);
            end();
            check(in, STATE_EXP(in, fn, exp), st, args);
        } else {
            static const char *names[] = {"fmi3EnterConfigurationMode", "fmi3ExitConfigurationMode",
                                          "fmi3GetIntervalDecimal", "fmi3SetShiftDecimal", "fmi3EvaluateDiscreteStates",
                                          "fmi3GetNumberOfVariableDependencies", "fmi3ActivateModelPartition"};
            int w = pick(r, 7);
            fmi3Float64 iv[1];
            fmi3IntervalQualifier q[1];
            size_t nd;
            fn = names[w];
            begin(fn, in);
            if (w == 0 || w == 1 || w == 4) st = call_alone(fn, H(in));
            else if (w == 2) st = (int)F3(fmi3GetIntervalDecimal)(H(in), vr, 1, iv, q);
            else if (w == 3) st = (int)F3(fmi3SetShiftDecimal)(H(in), vr, 1, iv);
            else if (w == 5) st = (int)F3(fmi3GetNumberOfVariableDependencies)(H(in), vr[0], &nd);
            else st = (int)F3(fmi3ActivateModelPartition)(H(in), vr[0], in->time);
            end();
            check(in, STATE_EXP(in, fn, EXP_OK), st, "");
        }
    }
}

/* ------------------------------------------------------------------ clocks (clocked FMUs) */
static void op_set_clock(Rng *r, Inst *in, int bad) {
    const char *fn = "fmi3SetClock";
    fmi3ValueReference vr[2] = {CLOCK_VR, CLOCK_VR};
    fmi3Clock v[2] = {fmi3ClockActive, fmi3ClockActive};
    size_t n = 1;
    int exp, st, k = bad ? pick(r, 4) : -1;
    char args[60];
    exp = clock_exp(in, in->clk.active || clock_due(in, in->time) == 1);
    if (k == 0) { v[0] = fmi3ClockInactive; exp = EXP_ERR; }                    /* canBeDeactivated = false */
    else if (k == 1) { vr[1] = VARS[0].vr == CLOCK_VR ? 0xFFFFFFFFu : VARS[0].vr; n = 2; exp = EXP_ERR; }
    else if (k == 2) { n = 0; exp = EXP_OK; }
    else if (k == 3) { vr[0] = unknown_vr(r); exp = EXP_ERR; }
    exp = STATE_EXP(in, fn, exp);
    snprintf(args, sizeof args, "n=%zu vr0=%u v0=%d t=%.17g", n, vr[0], (int)v[0], in->time);
    begin(fn, in);
    st = (int)F3(fmi3SetClock)(H(in), vr, n, v);
    end();
    check(in, exp, st, args);
    if (st == 0 && n) in->clk.active = 1;
}

static void op_get_clock(Rng *r, Inst *in, int bad) {
    const char *fn = "fmi3GetClock";
    fmi3ValueReference vr[1] = {bad ? unknown_vr(r) : CLOCK_VR};
    fmi3Clock v[1] = {7};
    int st, exp = STATE_EXP(in, fn, bad ? EXP_ERR : EXP_OK);
    begin(fn, in);
    st = (int)F3(fmi3GetClock)(H(in), vr, 1, v);
    end();
    check(in, exp, st, bad ? "unknown vr" : "the clock");
    if (st == 0 && !in->dirty && (v[0] != 0) != (in->clk.active != 0))
        violation("fmi3GetClock says %d, the clock is %sactive", (int)v[0], in->clk.active ? "" : "in");
}

static void op_update_discrete(Rng *r, Inst *in, int bad) {
    const char *fn = "fmi3UpdateDiscreteStates";
    fmi3Boolean b[5] = {1, 1, 1, 1, 1};
    fmi3Float64 next = 0;
    int st, exp = STATE_EXP(in, fn, bad ? EXP_ERR : EXP_OK);
    (void)r;
    begin(fn, in);
    st = (int)F3(fmi3UpdateDiscreteStates)(H(in), &b[0], &b[1], &b[2], &b[3], &b[4], bad ? NULL : &next);
    end();
    check(in, exp, st, bad ? "nextEventTime=NULL" : "");
    if (st == 0) {
        if (b[0] || b[1] || b[2] || b[3] || b[4]) violation("fmi3UpdateDiscreteStates asks for more (%d%d%d%d%d)",
                                                            b[0], b[1], b[2], b[3], b[4]);
        if (in->clk.active) { in->clk.active = 0; in->clk.n++; }
    }
}

static void op_enter_step(Rng *r, Inst *in, int bad) {
    (void)r; (void)bad;
    if (plain(in, "fmi3EnterStepMode", clock_exp(in, !in->clk.active), in->clk.active ? "clock active" : "") == 0)
        in->st = S_STEP;
}

static void op_enter_event(Rng *r, Inst *in, int bad) {
    (void)r; (void)bad;
    if (plain(in, "fmi3EnterEventMode", EXP_OK, "") == 0) in->st = S_EVENT;
}

static void op_activate(Rng *r, Inst *in, int bad) {
    const char *fn = "fmi3ActivateModelPartition";
    fmi3ValueReference vr = CLOCK_VR;
    double t = in->clk.t0 + (double)in->clk.n * INTERVAL;
    int st, exp = clock_exp(in, 1), k = bad ? pick(r, 5) : -1;
    char args[60];
    if (k == 0) { t += INTERVAL; exp = clock_exp(in, 0); }                       /* skips one */
    else if (k == 1) { t -= INTERVAL; exp = clock_exp(in, 0); }                  /* again, or before the start */
    else if (k == 2) { t = chance(r, 0.5) ? NAN : INFINITY; exp = EXP_ERR; }
    else if (k == 3) { vr = unknown_vr(r); exp = EXP_ERR; }
    else if (k == 4) { vr = VARS[0].vr == CLOCK_VR ? 0xFFFFFFFFu : VARS[0].vr; exp = EXP_ERR; }
    exp = STATE_EXP(in, fn, exp);
    snprintf(args, sizeof args, "clock=%u t=%.17g", vr, t);
    begin(fn, in);
    st = (int)F3(fmi3ActivateModelPartition)(H(in), vr, t);
    end();
    check(in, exp, st, args);
    if (st == 0) { in->clk.n++; in->clk.fresh = 1; in->time = t; }
}

static void op_interval(Rng *r, Inst *in, int bad) {
    const char *fn = "fmi3GetIntervalDecimal";
    fmi3ValueReference vr[1] = {bad ? unknown_vr(r) : CLOCK_VR};
    fmi3Float64 iv[1] = {-1};
    fmi3IntervalQualifier q[1] = {fmi3IntervalNotYetKnown};
    int st, exp = STATE_EXP(in, fn, bad ? EXP_ERR : EXP_OK);
    begin(fn, in);
    st = (int)F3(fmi3GetIntervalDecimal)(H(in), vr, 1, iv, q);
    end();
    check(in, exp, st, bad ? "unknown vr" : "the clock");
    if (st == 0 && (iv[0] != INTERVAL || q[0] != fmi3IntervalUnchanged))
        violation("fmi3GetIntervalDecimal: %g (qualifier %d), the clock is constant with interval %g", iv[0], (int)q[0],
                  INTERVAL);
}

/* A call with a NULL instance: Error, nothing else happens. */
static void op_null_instance(Rng *r) {
    int st;
    const char *fn;
    static Inst nobody;
    (void)r;
    if (V == 2) { fn = "fmi2DoStep"; begin(fn, &nobody); st = (int)F2(fmi2DoStep)(NULL, 0, 0.01, fmi2True); }
    else {
        fmi3Boolean a, b, c;
        fmi3Float64 d;
        fn = "fmi3DoStep"; begin(fn, &nobody); st = (int)F3(fmi3DoStep)(NULL, 0, 0.01, fmi3True, &a, &b, &c, &d);
    }
    end();
    check(NULL, EXP_ERR, st, "instance NULL");
    begin(V == 2 ? "fmi2FreeInstance" : "fmi3FreeInstance", &nobody);
    if (V == 2) F2(fmi2FreeInstance)(NULL); else F3(fmi3FreeInstance)(NULL);
    end();
}

/* ------------------------------------------------------------------ sequences */
typedef struct { Op op; const char *fn2, *fn3; int weight; int me_only; } Choice;

/* fn: the table row whose states make the call legal (for the legal-biased choice). */
static const Choice CHOICES[] = {
    {op_set_debug_logging, "fmi2SetDebugLogging", "fmi3SetDebugLogging", 1, 0},
    {op_setup_experiment, "fmi2SetupExperiment", "fmi3EnterInitializationMode", 2, 0},
    {op_enter_init, "fmi2EnterInitializationMode", "fmi3EnterInitializationMode", 3, 0},
    {op_exit_init, "fmi2ExitInitializationMode", "fmi3ExitInitializationMode", 3, 0},
    {op_terminate, "fmi2Terminate", "fmi3Terminate", 1, 0},
    {op_reset, "fmi2Reset", "fmi3Reset", 1, 0},
    {op_get, "fmi2GetReal", "fmi3GetFloat64", 4, 0},
    {op_set, "fmi2SetReal", "fmi3SetFloat64", 4, 0},
    {op_get_state, "fmi2GetFMUstate", "fmi3GetFMUState", 2, 0},
    {op_set_state, "fmi2SetFMUstate", "fmi3SetFMUState", 2, 0},
    {op_free_state, "fmi2FreeFMUstate", "fmi3FreeFMUState", 1, 0},
    {op_serialize, "fmi2SerializeFMUstate", "fmi3SerializeFMUState", 1, 0},
    {op_deserialize, "fmi2DeSerializeFMUstate", "fmi3DeserializeFMUState", 1, 0},
    {op_directional, "fmi2GetDirectionalDerivative", "fmi3GetDirectionalDerivative", 1, 0},
    {op_me_mode, "fmi2EnterContinuousTimeMode", "fmi3EnterContinuousTimeMode", 3, 1},
    {op_me_mode, "fmi2EnterEventMode", "fmi3EnterEventMode", 2, 1},
    {op_set_time, "fmi2SetTime", "fmi3SetTime", 2, 1},
    {op_states, "fmi2GetDerivatives", "fmi3GetContinuousStateDerivatives", 3, 1},
    {op_number_of, "fmi2GetContinuousStates", "fmi3GetNumberOfContinuousStates", 1, 1},
    {op_do_step, "fmi2DoStep", "fmi3DoStep", 8, 0},
    {op_cs_misc, "fmi2GetRealOutputDerivatives", "fmi3GetOutputDerivatives", 1, 0},
};
#define NCHOICES ((int)(sizeof CHOICES / sizeof CHOICES[0]))

/* Clocked FMUs: one step of the standard's call sequence for the clock from the instance's
 * state (initialise; Event Mode: activate the due clock, its inputs and outputs, end the
 * activation, Step Mode; Step Mode: step to the next activation, Event Mode there; Scheduled
 * Execution: inputs, the due activation, outputs; after an Error: Reset), each call checked
 * as any other: the sequences reach many activations between the hostile calls. */
static void values_r(Rng *r, Inst *in) {
    int set = chance(r, 0.5);
    op_values(r, in, 0, set, 'R', set ? "fmi3SetFloat64" : "fmi3GetFloat64");
}

static void op_advance(Rng *r, Inst *in, int bad) {
    (void)bad;
    switch (in->st) {
    case S_INST: op_setup_experiment(r, in, 0); break;
    case S_INIT: op_exit_init(r, in, 0); break;
    case S_EVENT:
        if (!in->clk.active && clock_due(in, in->time) == 1) op_set_clock(r, in, 0);
        else if (in->clk.active && chance(r, 0.6)) values_r(r, in);
        else if (in->clk.active) op_update_discrete(r, in, 0);
        else op_enter_step(r, in, 0);
        break;
    case S_STEP:
        if (clock_due(in, in->time) != 0) op_enter_event(r, in, 0);
        else op_do_step(r, in, 0);
        break;
    case S_ACT:
        if (chance(r, 0.4)) values_r(r, in);
        else op_activate(r, in, 0);
        break;
    default: op_reset(r, in, 0);
    }
}

/* Clocked FMUs: the clock's calls besides (FMI 3.0). */
static const Choice CLOCK_CHOICES[] = {
    {op_set_clock, NULL, "fmi3SetClock", 6, 0},
    {op_get_clock, NULL, "fmi3GetClock", 1, 0},
    {op_update_discrete, NULL, "fmi3UpdateDiscreteStates", 6, 0},
    {op_enter_step, NULL, "fmi3EnterStepMode", 5, 0},
    {op_enter_event, NULL, "fmi3EnterEventMode", 5, 0},
    {op_activate, NULL, "fmi3ActivateModelPartition", 10, 0},
    {op_interval, NULL, "fmi3GetIntervalDecimal", 1, 0},
    {op_advance, NULL, "fmi3Reset", 30, 0},
};
#define NCLOCK ((int)(sizeof CLOCK_CHOICES / sizeof CLOCK_CHOICES[0]))

static void call_one(Rng *r, Inst *in) {
    /* clocked FMUs: fewer hostile calls, so that sequences reach many activations */
    int legal[NCHOICES + NCLOCK], nl = 0, total = 0, bad = chance(r, CLOCKED ? 0.06 : 0.2);
    int n = NCHOICES + (CLOCKED ? NCLOCK : 0);
#define CHOICE(i) ((i) < NCHOICES ? &CHOICES[i] : &CLOCK_CHOICES[(i) - NCHOICES])
    for (int i = 0; i < n; i++) {
        const char *fn = V == 2 ? CHOICE(i)->fn2 : CHOICE(i)->fn3;
        if (CHOICE(i)->me_only && !HAS_ME) continue;
        if (allowed(in, fn)) { legal[nl++] = i; total += CHOICE(i)->weight; }
    }
    if (nl && chance(r, 0.75)) {
        int w = pick(r, total);
        for (int j = 0; j < nl; j++) {
            w -= CHOICE(legal[j])->weight;
            if (w < 0) { CHOICE(legal[j])->op(r, in, bad); return; }
        }
    }
    {
        int i = pick(r, n);
        CHOICE(i)->op(r, in, bad);
    }
#undef CHOICE
}

static void free_all(void) {
    for (int i = 0; i < MAXINST; i++)
        if (INST[i].h) op_free(&INST[i]);
    for (int i = 0; i < NBLOBS; i++) free(BLOBS[i].bytes);
    NBLOBS = 0;
    NSTATES_HELD = 0;
}

static void run_sequence(uint64_t seed, long long i) {
    Rng r = {seed ^ (0xD1B54A32D192ED03ull * (uint64_t)(i + 1))};
    int ncalls = 5 + pick(&r, MAXCALLS);
    ALLOC_RNG.s = r.s ^ 0x5bd1e995u;
    SEQ = i;
    CALL = 0;
    NTRACE = 0;
    NEXT_ID = 0;
    op_instantiate(&r, 0.0);
    for (int j = 0; j < ncalls; j++) {
        Inst *in = some_inst(&r);
        int what = pick(&r, 100);
        if (!in || what < 4) op_instantiate(&r, 0.4);
        else if (what < 6) op_free(in);
        else if (what == 6) op_null_instance(&r);
        else if (what == 7 && chance(&r, 0.2)) {            /* a burst: many instances, then freed */
            for (int b = 0; b < MAXINST; b++) op_instantiate(&r, 0.0);
            for (int b = 0; b < 3 * MAXINST; b++) { Inst *x = some_inst(&r); if (x) call_one(&r, x); }
            for (int b = 0; b < MAXINST; b++) if (INST[b].h && chance(&r, 0.7)) op_free(&INST[b]);
        } else call_one(&r, in);
    }
    free_all();
    n_seq++;
}

#include "cases.c"

int main(int argc, char **argv) {
    const char *lib = NULL, *vars = NULL, *case_name = NULL;
    long long first = 0, count = 1;
    for (int i = 1; i < argc; i++) {
        char *eq = strchr(argv[i], '=');
        const char *k = argv[i], *v = eq ? eq + 1 : "";
        if (!eq) { fprintf(stderr, "fuzz: argument %s is not key=value\n", argv[i]); return 2; }
        *eq = 0;
        if (!strcmp(k, "lib")) lib = v;
        else if (!strcmp(k, "fmi")) V = atoi(v);
        else if (!strcmp(k, "cs")) HAS_CS = atoi(v);
        else if (!strcmp(k, "me")) HAS_ME = atoi(v);
        else if (!strcmp(k, "dd")) HAS_DD = atoi(v);
        else if (!strcmp(k, "token")) TOKEN = v;
        else if (!strcmp(k, "vars")) vars = v;
        else if (!strcmp(k, "seed")) SEED = strtoull(v, NULL, 10);
        else if (!strcmp(k, "first")) first = atoll(v);
        else if (!strcmp(k, "count")) count = atoll(v);
        else if (!strcmp(k, "calls")) MAXCALLS = atoi(v);
        else if (!strcmp(k, "timeout")) TIMEOUT = atof(v);
        else if (!strcmp(k, "trace")) TRACE = atoi(v);
        else if (!strcmp(k, "case")) case_name = v;
        else if (!strcmp(k, "clock")) { CLOCKED = 1; CLOCK_VR = (unsigned)strtoul(v, NULL, 10); }
        else if (!strcmp(k, "interval")) INTERVAL = atof(v);
        else { fprintf(stderr, "fuzz: unknown argument %s\n", k); return 2; }
    }
    if (!lib || !TOKEN || !vars || (V != 2 && V != 3) || MAXCALLS < 1 || !(TIMEOUT > 0)
        || (CLOCKED && (V != 3 || !(INTERVAL > 0)))) {
        fprintf(stderr, "usage: fuzz lib=PATH fmi=2|3 cs=0|1 me=0|1 dd=0|1 token=T vars=FILE seed=S first=I count=N "
                        "[calls=60] [timeout=10] [trace=0] [clock=VR interval=T]\n");
        return 2;
    }
    if (load_vars(vars)) { fprintf(stderr, "fuzz: no variables in %s\n", vars); return 2; }
    LIB = dlopen(lib, RTLD_NOW | RTLD_LOCAL);
    if (!LIB) { fprintf(stderr, "fuzz: cannot load %s: %s\n", lib, dlerror()); return 2; }
    signal(SIGALRM, on_alarm);
    if (__sanitizer_set_death_callback) __sanitizer_set_death_callback(on_death);
    if (V == 2) {
        const char *ver = F2(fmi2GetVersion)(), *tp = F2(fmi2GetTypesPlatform)();
        if (strcmp(ver, "2.0") || strcmp(tp, "default")) { fprintf(stderr, "fuzz: version %s, types %s\n", ver, tp); return 1; }
    } else if (strcmp(F3(fmi3GetVersion)(), "3.0")) {
        fprintf(stderr, "fuzz: version %s\n", F3(fmi3GetVersion)());
        return 1;
    }
    if (case_name) return run_case(case_name);
    for (long long i = first; i < first + count; i++) run_sequence(SEED, i);
    summary("ok");
    return 0;
}
