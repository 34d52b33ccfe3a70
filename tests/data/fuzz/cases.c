/* pendulum-cosim fuzzer: the exact call sequences of the classes of failures found by fuzzing
 * the project's FMUs, replayed as regression cases (fuzz ... case=NAME; included by fuzz.c).
 * Each case prints "CASE NAME ok" and returns 0, or prints what went wrong and returns 1; a
 * hang is caught by the time limit, memory errors and undefined behaviour by the sanitizers.
 */

static int CASE_FAILS;
static Inst CASE_INST;               /* the environment given to the case's instances */

static void case_fail(const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    fprintf(stderr, "CASE FAILURE: ");
    vfprintf(stderr, fmt, ap);
    fprintf(stderr, "\n");
    va_end(ap);
    CASE_FAILS++;
}

/* Start a call of fn (the log capture and the time limit). */
static void c_begin(const char *fn) { begin(fn, &CASE_INST); }

/* The answer of the call begun last: want 0 (OK) or 3 (Error); for an Error with logging on,
 * a message naming the function and, if given, containing `word`; with logging off
 * (`logging` 0, FMI 3.0) no message at all. */
static void c_expect(int status, int want, int logging, const char *word) {
    end();
    if (TRACE) fprintf(stderr, "  %s -> %s%s%s\n", CUR_FN, status_name(status), LOG_COUNT ? " log: " : "", LOG_LAST);
    if (status != want) {
        case_fail("%s returned %s, expected %s (log: %s)", CUR_FN, status_name(status), status_name(want), LOG_LAST);
        return;
    }
    if (LOG_BAD_ENV) case_fail("%s: the log callback was given another environment", CUR_FN);
    if (!logging && LOG_COUNT) case_fail("%s: logging is off, yet the log callback was called: %s", CUR_FN, LOG_LAST);
    if (want == 3 && logging) {
        if (!LOG_NAMED) case_fail("%s: Error without a message naming the function (log: %s)", CUR_FN, LOG_LAST);
        else if (word && !strstr(LOG_LAST, word))
            case_fail("%s: the message does not say \"%s\": %s", CUR_FN, word, LOG_LAST);
    }
}

static fmi2CallbackFunctions CASE_CB2 = {logger2, calloc, free, NULL, &CASE_INST};

/* A new instance (cs: Co-Simulation, else Model Exchange), optionally initialised. */
static void *c_new(int cs, int logging, int init, double start) {
    void *h;
    if (V == 2) {
        c_begin("fmi2Instantiate");
        h = F2(fmi2Instantiate)("case", cs ? fmi2CoSimulation : fmi2ModelExchange, TOKEN, NULL, &CASE_CB2, fmi2False,
                                logging);
        end();
        if (h && init) {
            F2(fmi2SetupExperiment)(h, fmi2False, 0, start, fmi2False, 0);
            F2(fmi2EnterInitializationMode)(h);
            if (F2(fmi2ExitInitializationMode)(h) != fmi2OK) case_fail("initialisation failed");
        }
    } else {
        c_begin(cs ? "fmi3InstantiateCoSimulation" : "fmi3InstantiateModelExchange");
        h = cs ? F3(fmi3InstantiateCoSimulation)("case", TOKEN, NULL, fmi3False, logging, fmi3False, fmi3False, NULL, 0,
                                                &CASE_INST, logger3, NULL)
               : F3(fmi3InstantiateModelExchange)("case", TOKEN, NULL, fmi3False, logging, &CASE_INST, logger3);
        end();
        if (h && init) {
            F3(fmi3EnterInitializationMode)(h, fmi3False, 0, start, fmi3False, 0);
            if (F3(fmi3ExitInitializationMode)(h) != fmi3OK) case_fail("initialisation failed");
        }
    }
    if (!h) case_fail("instantiation failed: %s", LOG_LAST);
    return h;
}

static void c_free(void *h) {
    if (V == 2) F2(fmi2FreeInstance)(h); else F3(fmi3FreeInstance)(h);
}

/* fn, a function of the instance alone, called on h: the answer want (see c_expect; logging on) */
static void c_alone(void *h, const char *fn, int want, const char *word) {
    c_begin(fn);
    c_expect(call_alone(fn, h), want, 1, word);
}

/* the same on a new initialised instance (cs: Co-Simulation, else Model Exchange), freed after */
static void c_alone_new(int cs, const char *fn, int want, const char *word) {
    void *h = c_new(cs, 1, 1, 0.0);
    c_alone(h, fn, want, word);
    c_free(h);
}

static int c_do_step(void *h, double t, double dt) {
    fmi3Boolean a, b, c;
    fmi3Float64 last;
    c_begin(V == 2 ? "fmi2DoStep" : "fmi3DoStep");
    return V == 2 ? (int)F2(fmi2DoStep)(h, t, dt, fmi2True) : (int)F3(fmi3DoStep)(h, t, dt, fmi3True, &a, &b, &c, &last);
}

static const Var *first_var(char type, char caus) {
    for (int i = 0; i < NVARS; i++)
        if (VARS[i].type == type && (!caus || VARS[i].caus == caus)) return &VARS[i];
    return NULL;
}

/* Finding 1: doStep at a non-finite or out-of-range communication point, or with a
 * non-finite, zero, negative or overflowing step, is refused with a message (no hang, no
 * undefined conversion); the instance is usable again after Reset. */
static void case_nonfinite_time(void) {
    const double ts[] = {NAN, INFINITY, -INFINITY};
    const double hs[] = {NAN, INFINITY, 0.0, -0.01, -INFINITY};
    for (int i = 0; i < 3; i++) {
        void *h = c_new(1, 1, 1, 0.0);
        c_expect(c_do_step(h, ts[i], 0.01), 3, 1, "not finite");
        c_alone(h, VFN(Reset), 0, NULL);
        c_free(h);
    }
    for (int i = 0; i < 5; i++) {
        void *h = c_new(1, 1, 1, 0.0);
        c_expect(c_do_step(h, 0.0, hs[i]), 3, 1, "step size");
        c_free(h);
    }
    {   /* t + h overflows */
        void *h = c_new(1, 1, 1, 0.0);
        c_expect(c_do_step(h, 0.0, 1.7976931348623157e308), 3, 1, NULL);
        c_free(h);
    }
    {   /* a start time too far from zero for the sample period: refused at the step, not converted */
        void *h = c_new(1, 1, 1, 1e300);
        c_expect(c_do_step(h, 1e300, 1e290), 3, 1, NULL);
        c_free(h);
    }
    {   /* the time stays usable: a normal run after the refusals */
        void *h = c_new(1, 1, 1, 0.0);
        for (int k = 0; k < 10; k++) c_expect(c_do_step(h, k * 0.01, 0.01), 0, 1, NULL);
        c_free(h);
    }
}

/* Finding 2: value references at or above 2^31 through every integer (and the other)
 * getters and setters: Error with a message, no signed overflow on the way. */
static void case_vr_overflow(void) {
    const unsigned vrs[] = {0x80000000u, 0xFFFFFFFFu, 0x7FFFFFFFu, 0x80000001u};
    for (int i = 0; i < 4; i++) {
        for (int f = 0; f < 6; f++) {
            void *h = c_new(1, 1, 0, 0.0);
            unsigned vr[1] = {vrs[i]};
            int st;
            if (V == 2) {
                fmi2Integer iv[1] = {1};
                fmi2Real rv[1] = {1};
                fmi2Boolean bv[1] = {1};
                F2(fmi2EnterInitializationMode)(h);
                static const char *n2[] = {"fmi2GetInteger", "fmi2SetInteger", "fmi2GetReal", "fmi2SetReal",
                                           "fmi2GetBoolean", "fmi2SetBoolean"};
                c_begin(n2[f]);
                st = f == 0 ? (int)F2(fmi2GetInteger)(h, vr, 1, iv) : f == 1 ? (int)F2(fmi2SetInteger)(h, vr, 1, iv)
                   : f == 2 ? (int)F2(fmi2GetReal)(h, vr, 1, rv) : f == 3 ? (int)F2(fmi2SetReal)(h, vr, 1, rv)
                   : f == 4 ? (int)F2(fmi2GetBoolean)(h, vr, 1, bv) : (int)F2(fmi2SetBoolean)(h, vr, 1, bv);
            } else {
                fmi3Int32 i32[1] = {1};
                fmi3Int64 i64[1] = {1};
                static const char *n3[] = {"fmi3GetInt32", "fmi3SetInt32", "fmi3GetInt64", "fmi3SetInt64",
                                           "fmi3GetFloat64", "fmi3SetFloat64"};
                fmi3Float64 rv[1] = {1};
                F3(fmi3EnterInitializationMode)(h, fmi3False, 0, 0, fmi3False, 0);
                c_begin(n3[f]);
                st = f == 0 ? (int)F3(fmi3GetInt32)(h, vr, 1, i32, 1) : f == 1 ? (int)F3(fmi3SetInt32)(h, vr, 1, i32, 1)
                   : f == 2 ? (int)F3(fmi3GetInt64)(h, vr, 1, i64, 1) : f == 3 ? (int)F3(fmi3SetInt64)(h, vr, 1, i64, 1)
                   : f == 4 ? (int)F3(fmi3GetFloat64)(h, vr, 1, rv, 1) : (int)F3(fmi3SetFloat64)(h, vr, 1, rv, 1);
            }
            c_expect(st, 3, 1, "value reference");
            c_free(h);
        }
    }
}

/* Finding 3 (FMI 3.0): no log callback with loggingOn = false, errors included (a refused
 * call, a refused value, a refused instantiation, Scheduled Execution); fmi3SetDebugLogging
 * turns the messages on. FMI 2.0: errors are reported whatever loggingOn. */
static void case_logging_off(void) {
    int log_errors = V == 2;
    void *h = c_new(1, 0, 0, 0.0), *g;
    c_expect(c_do_step(h, 0, 0.01), 3, log_errors, "Instantiated");
    c_free(h);
    h = c_new(1, 0, 1, 0.0);
    {
        unsigned vr[1] = {0xFFFFFFF0u};
        double v[1] = {0};
        c_begin(V == 2 ? "fmi2SetReal" : "fmi3SetFloat64");
        c_expect(V == 2 ? (int)F2(fmi2SetReal)(h, vr, 1, v) : (int)F3(fmi3SetFloat64)(h, vr, 1, v, 1), 3, log_errors, NULL);
    }
    c_free(h);
    if (V == 3) {
        c_begin("fmi3InstantiateCoSimulation");
        g = F3(fmi3InstantiateCoSimulation)("case", "{wrong}", NULL, fmi3False, fmi3False, fmi3False, fmi3False, NULL, 0,
                                            &CASE_INST, logger3, NULL);
        c_expect(g ? 0 : 3, 3, 0, NULL);
        c_begin("fmi3InstantiateScheduledExecution");
        g = F3(fmi3InstantiateScheduledExecution)("case", TOKEN, NULL, fmi3False, fmi3False, &CASE_INST, logger3, NULL,
                                                  NULL, NULL);
        c_expect(g ? 0 : 3, 3, 0, NULL);
        h = c_new(1, 0, 0, 0.0);
        c_begin("fmi3SetDebugLogging");
        c_expect((int)F3(fmi3SetDebugLogging)(h, fmi3True, 0, NULL), 0, 0, NULL);
        c_expect(c_do_step(h, 0, 0.01), 3, 1, "Instantiated");
        c_free(h);
    }
}

/* Finding 3 (FMI 3.0): eventModeUsed = true is refused (hasEventMode = false), and an
 * instance leaves Initialization Mode into Step Mode, where fmi3EnterEventMode is refused. */
static void case_event_mode_used(void) {
    void *h;
    if (V == 2) return;
    c_begin("fmi3InstantiateCoSimulation");
    h = F3(fmi3InstantiateCoSimulation)("case", TOKEN, NULL, fmi3False, fmi3True, fmi3True, fmi3False, NULL, 0,
                                        &CASE_INST, logger3, NULL);
    c_expect(h ? 0 : 3, 3, 1, "eventModeUsed");
    if (h) c_free(h);
    h = c_new(1, 1, 1, 0.0);
    c_expect(c_do_step(h, 0, 0.01), 0, 1, NULL);
    c_alone(h, "fmi3EnterEventMode", 3, "Co-Simulation");
    c_free(h);
}

/* Finding 3: after a call returned Error only what the standard allows is accepted (Reset,
 * FreeInstance, SetDebugLogging, the FMU-state functions, the getters for debugging): no
 * doStep, no setter, no Terminate; Reset or a saved state make the instance usable again. */
static void case_after_error(void) {
    void *h = c_new(1, 1, 1, 0.0), *s = NULL;
    unsigned vr[1] = {0xFFFFFF00u};
    double v[1] = {1};
    const Var *out = first_var('R', 'o');
    unsigned ovr[1] = {out ? out->vr : 0};
    c_begin(V == 2 ? "fmi2GetFMUstate" : "fmi3GetFMUState");
    c_expect(V == 2 ? (int)F2(fmi2GetFMUstate)(h, &s) : (int)F3(fmi3GetFMUState)(h, &s), 0, 1, NULL);
    c_begin(V == 2 ? "fmi2SetReal" : "fmi3SetFloat64");
    c_expect(V == 2 ? (int)F2(fmi2SetReal)(h, vr, 1, v) : (int)F3(fmi3SetFloat64)(h, vr, 1, v, 1), 3, 1, "value reference");
    c_expect(c_do_step(h, 0, 0.01), 3, 1, "after a call returned Error");
    c_begin(V == 2 ? "fmi2GetReal" : "fmi3GetFloat64");       /* values for debugging: allowed */
    c_expect(V == 2 ? (int)F2(fmi2GetReal)(h, ovr, 1, v) : (int)F3(fmi3GetFloat64)(h, ovr, 1, v, 1), 0, 1, NULL);
    c_begin(V == 2 ? "fmi2SetReal" : "fmi3SetFloat64");
    c_expect(V == 2 ? (int)F2(fmi2SetReal)(h, NULL, 0, NULL) : (int)F3(fmi3SetFloat64)(h, NULL, 0, NULL, 0), 3, 1, "Error");
    c_alone(h, VFN(Terminate), 3, "Error");
    c_begin(V == 2 ? "fmi2SetFMUstate" : "fmi3SetFMUState");
    c_expect(V == 2 ? (int)F2(fmi2SetFMUstate)(h, s) : (int)F3(fmi3SetFMUState)(h, s), 0, 1, NULL);
    c_expect(c_do_step(h, 0, 0.01), 0, 1, NULL);
    c_begin(V == 2 ? "fmi2SetReal" : "fmi3SetFloat64");
    c_expect(V == 2 ? (int)F2(fmi2SetReal)(h, vr, 1, v) : (int)F3(fmi3SetFloat64)(h, vr, 1, v, 1), 3, 1, NULL);
    c_alone(h, VFN(Reset), 0, NULL);
    c_begin(V == 2 ? "fmi2FreeFMUstate" : "fmi3FreeFMUState");
    c_expect(V == 2 ? (int)F2(fmi2FreeFMUstate)(h, &s) : (int)F3(fmi3FreeFMUState)(h, &s), 0, 1, NULL);
    c_free(h);
    h = c_new(1, 1, 1, 0.0);
    c_expect(c_do_step(h, 0, 0.01), 0, 1, NULL);
    c_free(h);
}

/* Finding 4: calls the state tables forbid, each on a fresh instance: Error with a message
 * naming the function and the state; and GetDirectionalDerivative in Terminated, allowed. */
static void case_forbidden_states(void) {
    const Var *out = first_var('R', 'o'), *in = first_var('R', 'i');
    unsigned ovr[1] = {out ? out->vr : 0};
    double v[8] = {0};
    size_t n;
    void *h;
    /* a getter in Instantiated */
    h = c_new(1, 1, 0, 0.0);
    c_begin(V == 2 ? "fmi2GetReal" : "fmi3GetFloat64");
    c_expect(V == 2 ? (int)F2(fmi2GetReal)(h, ovr, 1, v) : (int)F3(fmi3GetFloat64)(h, ovr, 1, v, 1), 3, 1, "Instantiated");
    c_free(h);
    /* a setter with no values in Terminated */
    h = c_new(1, 1, 1, 0.0);
    c_alone(h, VFN(Terminate), 0, NULL);
    c_begin(V == 2 ? "fmi2SetReal" : "fmi3SetFloat64");
    c_expect(V == 2 ? (int)F2(fmi2SetReal)(h, NULL, 0, NULL) : (int)F3(fmi3SetFloat64)(h, NULL, 0, NULL, 0), 3, 1, "Terminated");
    c_free(h);
    /* Model Exchange functions on a Co-Simulation instance */
    for (int f = 0; f < 3; f++) {
        h = c_new(1, 1, 1, 0.0);
        if (V == 2) {
            c_begin(f == 0 ? "fmi2SetTime" : f == 1 ? "fmi2GetDerivatives" : "fmi2EnterEventMode");
            c_expect(f == 0 ? (int)F2(fmi2SetTime)(h, 0.0) : f == 1 ? (int)F2(fmi2GetDerivatives)(h, v, (size_t)NX)
                            : (int)F2(fmi2EnterEventMode)(h), 3, 1, "Model Exchange");
        } else {
            c_begin(f == 0 ? "fmi3SetTime" : f == 1 ? "fmi3GetNumberOfContinuousStates" : "fmi3UpdateDiscreteStates");
            if (f == 2) {
                fmi3Boolean b[5];
                fmi3Float64 next;
                c_expect((int)F3(fmi3UpdateDiscreteStates)(h, &b[0], &b[1], &b[2], &b[3], &b[4], &next), 3, 1, "Step Mode");
            } else {
                c_expect(f == 0 ? (int)F3(fmi3SetTime)(h, 0.0) : (int)F3(fmi3GetNumberOfContinuousStates)(h, &n), 3, 1,
                         "Model Exchange");
            }
        }
        c_free(h);
    }
    if (V == 3) {   /* fmi3EnterStepMode in Step Mode, fmi3EvaluateDiscreteStates, fmi3GetNumberOfEventIndicators */
        c_alone_new(1, "fmi3EnterStepMode", 3, "Step Mode");
        c_alone_new(1, "fmi3EvaluateDiscreteStates", 3, NULL);
    }
    if (HAS_ME) {
        /* Model Exchange: SetTime in Event Mode, the numbers in Continuous-Time Mode, EnterEventMode in Event Mode */
        h = c_new(0, 1, 1, 0.0);
        c_begin(V == 2 ? "fmi2SetTime" : "fmi3SetTime");
        c_expect(V == 2 ? (int)F2(fmi2SetTime)(h, 0.01) : (int)F3(fmi3SetTime)(h, 0.01), 3, 1, "Event Mode");
        c_free(h);
        h = c_new(0, 1, 1, 0.0);
        c_begin(V == 2 ? "fmi2DoStep" : "fmi3DoStep");
        c_expect(c_do_step(h, 0, 0.01), 3, 1, "Co-Simulation");
        c_free(h);
        if (V == 3) {
            c_alone_new(0, "fmi3EnterEventMode", 3, "Event Mode");
            h = c_new(0, 1, 1, 0.0);
            c_alone(h, "fmi3EnterContinuousTimeMode", 0, NULL);
            c_begin("fmi3GetNumberOfContinuousStates");
            c_expect((int)F3(fmi3GetNumberOfContinuousStates)(h, &n), 3, 1, "Continuous-Time Mode");
            c_free(h);
            h = c_new(0, 1, 0, 0.0);
            c_begin("fmi3GetNumberOfEventIndicators");
            c_expect((int)F3(fmi3GetNumberOfEventIndicators)(h, &n), 0, 1, NULL);   /* allowed in Instantiated */
            F3(fmi3EnterInitializationMode)(h, fmi3False, 0, 0, fmi3False, 0);
            c_begin("fmi3GetNumberOfEventIndicators");
            c_expect((int)F3(fmi3GetNumberOfEventIndicators)(h, &n), 3, 1, "Initialization Mode");
            c_free(h);
        }
    }
    if (HAS_DD && out && in) {   /* directional derivatives in Terminated: allowed */
        unsigned kvr[1] = {in->vr};
        double seed[1] = {1};
        h = c_new(1, 1, 1, 0.0);
        c_alone(h, VFN(Terminate), 0, NULL);
        c_begin(V == 2 ? "fmi2GetDirectionalDerivative" : "fmi3GetDirectionalDerivative");
        c_expect(V == 2 ? (int)F2(fmi2GetDirectionalDerivative)(h, ovr, 1, kvr, 1, seed, v)
                        : (int)F3(fmi3GetDirectionalDerivative)(h, ovr, 1, kvr, 1, seed, 1, v, 1), 0, 1, NULL);
        if (V == 3) {
            c_begin("fmi3GetAdjointDerivative");
            c_expect((int)F3(fmi3GetAdjointDerivative)(h, ovr, 1, kvr, 1, seed, 1, v, 1), 0, 1, NULL);
        }
        c_free(h);
    }
}

/* FMU states: a freed state, another instance's, and changed serialised bytes are refused
 * (never read); a NULL logger never crashes. */
static void case_fmu_states(void) {
    void *a = c_new(1, 1, 1, 0.0), *b = c_new(1, 1, 1, 0.0), *s = NULL, *t = NULL, *u = NULL;
    size_t size = 0;
    unsigned char *bytes;
    c_begin(V == 2 ? "fmi2GetFMUstate" : "fmi3GetFMUState");
    c_expect(V == 2 ? (int)F2(fmi2GetFMUstate)(a, &s) : (int)F3(fmi3GetFMUState)(a, &s), 0, 1, NULL);
    c_begin(V == 2 ? "fmi2SetFMUstate" : "fmi3SetFMUState");
    c_expect(V == 2 ? (int)F2(fmi2SetFMUstate)(b, s) : (int)F3(fmi3SetFMUState)(b, s), 3, 1, "another instance");
    c_begin(V == 2 ? "fmi2SerializedFMUstateSize" : "fmi3SerializedFMUStateSize");
    c_expect(V == 2 ? (int)F2(fmi2SerializedFMUstateSize)(a, s, &size) : (int)F3(fmi3SerializedFMUStateSize)(a, s, &size),
             0, 1, NULL);
    bytes = (unsigned char *)malloc(size);
    c_begin(V == 2 ? "fmi2SerializeFMUstate" : "fmi3SerializeFMUState");
    c_expect(V == 2 ? (int)F2(fmi2SerializeFMUstate)(a, s, (fmi2Byte *)bytes, size)
                    : (int)F3(fmi3SerializeFMUState)(a, s, bytes, size), 0, 1, NULL);
    t = s;
    c_begin(V == 2 ? "fmi2FreeFMUstate" : "fmi3FreeFMUState");
    c_expect(V == 2 ? (int)F2(fmi2FreeFMUstate)(a, &s) : (int)F3(fmi3FreeFMUState)(a, &s), 0, 1, NULL);
    if (s) case_fail("FreeFMUState did not set the state to NULL");
    c_begin(V == 2 ? "fmi2SetFMUstate" : "fmi3SetFMUState");
    c_expect(V == 2 ? (int)F2(fmi2SetFMUstate)(a, t) : (int)F3(fmi3SetFMUState)(a, t), 3, 1, "freed");
    c_free(a);
    c_begin(V == 2 ? "fmi2Reset" : "fmi3Reset");
    c_expect(V == 2 ? (int)F2(fmi2Reset)(b) : (int)F3(fmi3Reset)(b), 0, 1, NULL);
    bytes[size / 2] ^= 0x40;
    c_begin(V == 2 ? "fmi2DeSerializeFMUstate" : "fmi3DeserializeFMUState");
    c_expect(V == 2 ? (int)F2(fmi2DeSerializeFMUstate)(b, (fmi2Byte *)bytes, size, &u)
                    : (int)F3(fmi3DeserializeFMUState)(b, bytes, size, &u), 3, 1, "changed");
    bytes[size / 2] ^= 0x40;
    c_begin(V == 2 ? "fmi2Reset" : "fmi3Reset");
    c_expect(V == 2 ? (int)F2(fmi2Reset)(b) : (int)F3(fmi3Reset)(b), 0, 1, NULL);
    c_begin(V == 2 ? "fmi2DeSerializeFMUstate" : "fmi3DeserializeFMUState");
    c_expect(V == 2 ? (int)F2(fmi2DeSerializeFMUstate)(b, (fmi2Byte *)bytes, size, &u)
                    : (int)F3(fmi3DeserializeFMUState)(b, bytes, size, &u), 0, 1, NULL);
    c_begin(V == 2 ? "fmi2SetFMUstate" : "fmi3SetFMUState");
    c_expect(V == 2 ? (int)F2(fmi2SetFMUstate)(b, u) : (int)F3(fmi3SetFMUState)(b, u), 0, 1, NULL);
    c_expect(c_do_step(b, 0, 0.01), 0, 1, NULL);
    free(bytes);
    c_free(b);                      /* frees the state u left in it */
    /* a NULL logger: refusals still answered, nothing crashes */
    if (V == 2) {
        fmi2CallbackFunctions cb = {NULL, calloc, free, NULL, NULL};
        a = F2(fmi2Instantiate)("case", fmi2CoSimulation, TOKEN, NULL, &cb, fmi2False, fmi2True);
        if (!a) case_fail("instantiation with a NULL logger failed");
        else {
            c_expect(c_do_step(a, 0, 0.01), 3, 0, NULL);
            c_free(a);
        }
    } else {
        a = F3(fmi3InstantiateCoSimulation)("case", TOKEN, NULL, fmi3False, fmi3True, fmi3False, fmi3False, NULL, 0,
                                            NULL, NULL, NULL);
        if (!a) case_fail("instantiation with a NULL logger failed");
        else {
            c_expect(c_do_step(a, 0, 0.01), 3, 0, NULL);
            c_free(a);
        }
    }
}

/* Found by the soak run: a setter refused at a later value had applied the earlier ones (a
 * hostile value among them then made the derivatives read for debugging non-finite). A
 * refused call now changes nothing: the values read after the Error are those before it. */
static void case_atomic_set(void) {
    const Var *in = first_var('R', 'i'), *iv = first_var('I', 'p');
    unsigned vr[2];
    double before[1], after[1], v[2];
    void *h = c_new(1, 1, 0, 0.0);
    if (!in) in = first_var('R', 'p');                 /* a source: a parameter, settable here */
    if (!in) { case_fail("no settable Real variable"); c_free(h); return; }
    if (V == 2) F2(fmi2EnterInitializationMode)(h); else F3(fmi3EnterInitializationMode)(h, fmi3False, 0, 0, fmi3False, 0);
    vr[0] = in->vr; vr[1] = 0xFFFFFFF0u;
    c_begin(V == 2 ? "fmi2GetReal" : "fmi3GetFloat64");
    c_expect(V == 2 ? (int)F2(fmi2GetReal)(h, vr, 1, before) : (int)F3(fmi3GetFloat64)(h, vr, 1, before, 1), 0, 1, NULL);
    v[0] = before[0] + 0.25; v[1] = 1.0;
    c_begin(V == 2 ? "fmi2SetReal" : "fmi3SetFloat64");
    c_expect(V == 2 ? (int)F2(fmi2SetReal)(h, vr, 2, v) : (int)F3(fmi3SetFloat64)(h, vr, 2, v, 2), 3, 1, "value reference");
    c_begin(V == 2 ? "fmi2GetReal" : "fmi3GetFloat64");     /* allowed after the Error: for debugging */
    c_expect(V == 2 ? (int)F2(fmi2GetReal)(h, vr, 1, after) : (int)F3(fmi3GetFloat64)(h, vr, 1, after, 1), 0, 1, NULL);
    if (after[0] != before[0]) case_fail("the refused setter changed %u from %g to %g", vr[0], before[0], after[0]);
    c_free(h);
    if (iv) {   /* the same with an Integer parameter */
        int i0[2] = {0, 0}, i1[2] = {0, 0};
        h = c_new(1, 1, 0, 0.0);
        vr[0] = iv->vr; vr[1] = 0xFFFFFFF0u;
        if (V == 2) {
            F2(fmi2EnterInitializationMode)(h);
            F2(fmi2GetInteger)(h, vr, 1, i0);
            i1[0] = i0[0] < 0x7FFFFFFF ? i0[0] + 1 : i0[0] - 1;
            c_begin("fmi2SetInteger");
            c_expect((int)F2(fmi2SetInteger)(h, vr, 2, i1), 3, 1, "value reference");
            F2(fmi2GetInteger)(h, vr, 1, i1);
        } else {
            F3(fmi3EnterInitializationMode)(h, fmi3False, 0, 0, fmi3False, 0);
            F3(fmi3GetInt32)(h, vr, 1, i0, 1);
            i1[0] = i0[0] < 0x7FFFFFFF ? i0[0] + 1 : i0[0] - 1;
            c_begin("fmi3SetInt32");
            c_expect((int)F3(fmi3SetInt32)(h, vr, 2, i1, 2), 3, 1, "value reference");
            F3(fmi3GetInt32)(h, vr, 1, i1, 1);
        }
        if (i1[0] != i0[0]) case_fail("the refused setter changed %u from %d to %d", vr[0], i0[0], i1[0]);
        c_free(h);
    }
}

static const struct { const char *name; void (*run)(void); } CASES[] = {
    {"nonfinite_time", case_nonfinite_time}, {"vr_overflow", case_vr_overflow}, {"logging_off", case_logging_off},
    {"event_mode_used", case_event_mode_used}, {"after_error", case_after_error},
    {"forbidden_states", case_forbidden_states}, {"fmu_states", case_fmu_states}, {"atomic_set", case_atomic_set}};

static int run_case(const char *name) {
    for (size_t i = 0; i < sizeof CASES / sizeof CASES[0]; i++)
        if (!strcmp(CASES[i].name, name)) {
            CUR_FN = name;
            CASES[i].run();
            if (CASE_FAILS) { fprintf(stderr, "CASE %s failed (%d)\n", name, CASE_FAILS); return 1; }
            printf("CASE %s ok\n", name);
            return 0;
        }
    fprintf(stderr, "fuzz: no case %s\n", name);
    return 2;
}
