/* ClockLab: a hand-written FMI 3.0 test FMU with clocks of every kind, with Model
 * Exchange, Co-Simulation (Event Mode) and Scheduled Execution interfaces; independent of
 * pendulum-cosim's code. It checks the call rules of the FMI 3.0 standard for clocks that
 * it receives (see ../common/clock_base.h for how a violation is reported).
 *
 * Clocks (value reference, timing):
 *   1 cConst     constant, every 0.1 s (counter form 1/10)       partition: constCount++,
 *                yConst = 2 uConst + constCount; cOut ticks when constCount % 3 == 0;
 *                the countdown is announced when constCount % 4 == 0
 *   2 cFixed     fixed, intervalDecimal 0.2 s, shift 0.1 s (set by the importer)
 *                fixedValue = yConst of the same instant + 1 (cConst's partition first)
 *   3 cFixedP    fixed without intervalDecimal: interval pFixedInterval, shift pFixedShift
 *   4 cTunable   tunable, 0.4 s = 4/10 from 0.1 s = 1/10 (set by the importer as a fraction)
 *   5 cChanging  changing: first after 0.1 s, then 0.1 (1 + n % 3) s after its n-th tick
 *   6 cCountdown countdown: pCountdown s after its announcement
 *   7 cTrigger   triggered input: trigSum += trigValue, trigCount++ (needs a second
 *                super-dense instant in ME and CS)
 *   8 cOut       triggered output (see cConst), outValue = yConst
 *   9 cAlarm     triggered output at the state event x = pThreshold (x' = uRate, reset to
 *                0 at the event): an event indicator in ME, an early return in CS
 * A time event at pTimeEvent (if >= 0) counts in timeEvents (ME and CS). uMode (Int32,
 * discrete, no clock) is copied to modeSeen; ME and CS take it only in Event Mode. pFailAt (if >= 0):
 * the first fmi3UpdateDiscreteStates (SE: fmi3ActivateModelPartition) at or after that time
 * returns fmi3Error ("requested failure"), to test what an importer does after an error.
 *
 * Rules checked (a violation each): SetClock only in Event Mode, only on input clocks,
 * only to activate, each time-based clock exactly at its time (not early, not late, not
 * skipped, not twice in one Event Mode when periodic); clocked variables got or set only
 * while one of their clocks is active (SE: got after their partition ran, never a get
 * after a set without an activation between); fmi3GetClock only in Event Mode (SE: only in
 * the clockUpdate callback) and every output clock read before the instant ends; the
 * intervals: set in Initialization Mode for cFixed and cTunable, asked (with the shift)
 * for cFixedP, asked for cChanging and cCountdown; afterwards the countdown's interval read
 * after the last fmi3UpdateDiscreteStates of every Event Mode (SE: in every clockUpdate
 * callback), the changing clock's after each of its ticks; no clock left active when
 * Event Mode is left; fmi3DoStep only in Step Mode, at the FMU's time, never over an
 * activation or the time event, never after eventHandlingNeeded without Event Mode
 * between; no get after a set in Step Mode without fmi3DoStep between; SE: partitions
 * activated once per time, in priority order, at increasing times. */
#define WITH_MODEL_EXCHANGE
#include "../common/clock_base.h"

#define TOKEN "{4b0c9a52-7e1d-4d8e-9c3a-clocklab0001}"
enum { C_CONST, C_FIXED, C_FIXEDP, C_TUNABLE, C_CHANGING, C_COUNTDOWN, C_TRIGGER, C_OUT, C_ALARM, N_CLOCKS };
static const char *CLOCK[N_CLOCKS] = {"cConst", "cFixed", "cFixedP", "cTunable", "cChanging", "cCountdown",
                                      "cTrigger", "cOut", "cAlarm"};
static const int PRIORITY[N_CLOCKS] = {0, 1, 2, 3, 4, 5, 6, -1, -1};
static const bool FRACTION[N_CLOCKS] = {true, false, false, true, false, false, false, false, false};
enum { Q_NOT_YET_KNOWN = 0, Q_UNCHANGED = 1, Q_CHANGED = 2 };

/* value references */
enum { VR_TIME = 0, VR_UCONST = 20, VR_YCONST, VR_CONSTCOUNT, VR_FIXEDCOUNT, VR_FIXEDPCOUNT, VR_TUNABLECOUNT,
       VR_CHANGINGCOUNT, VR_COUNTDOWNCOUNT, VR_TRIGVALUE, VR_TRIGSUM, VR_TRIGCOUNT, VR_OUTVALUE, VR_ALARMCOUNT, VR_X,
       VR_URATE, VR_LASTTIME, VR_FIXEDSEEN, VR_VIOLATIONS, VR_FIXEDVALUE, VR_TIMEEVENTS, VR_PFIXEDINTERVAL,
       VR_PFIXEDSHIFT, VR_PCOUNTDOWN, VR_PTHRESHOLD, VR_PTIMEEVENT = 45, VR_DERX = 46, VR_Z = 47, VR_PFAILAT = 48,
       VR_UMODE = 49, VR_MODESEEN = 50 };

typedef struct {
    Base b;
    double interval[N_CLOCKS], shift[N_CLOCKS], next_due[N_CLOCKS], last_activation[N_CLOCKS];
    bool active[N_CLOCKS], activated_in_event[N_CLOCKS], ever[N_CLOCKS], out_pending[N_CLOCKS];
    bool interval_set[N_CLOCKS], interval_read[N_CLOCKS], shift_read[N_CLOCKS];
    int qualifier[N_CLOCKS];
    double pending_interval[N_CLOCKS];
    bool changing_unread, countdown_read_after_uds, countdown_read_in_callback, in_callback, alarm_pending;
    bool ehn_pending, set_since_step, set_since_activation, time_event_done, second_instant;
    double se_time;
    int se_last_priority;
    /* variables */
    double uConst, trigValue, uRate, x, lastTime, fixedSeen, yConstLast, trigSumPrev, fixedValueLast, outValueLast;
    double pFixedInterval, pFixedShift, pCountdown, pThreshold, pTimeEvent, pFailAt;
    int32_t constCount, fixedCount, fixedPCount, tunableCount, changingCount, countdownCount, trigCount, alarmCount;
    int32_t timeEvents, uMode;
} Lab;

static int clock_of_vr(fmi3ValueReference vr) { return (vr >= 1 && vr <= N_CLOCKS) ? (int)vr - 1 : -1; }
static bool input_clock(int k) { return k >= 0 && k <= C_TRIGGER; }
static bool time_based(int k) { return k >= 0 && k <= C_COUNTDOWN; }
static bool periodic(int k) { return k >= 0 && k <= C_TUNABLE; }

/* the clocks a variable belongs to (-1: none) */
static int clock_of_variable(fmi3ValueReference vr) {
    switch (vr) {
    case VR_UCONST: case VR_YCONST: case VR_CONSTCOUNT: return C_CONST;
    case VR_FIXEDCOUNT: case VR_FIXEDVALUE: return C_FIXED;
    case VR_FIXEDPCOUNT: return C_FIXEDP;
    case VR_TUNABLECOUNT: return C_TUNABLE;
    case VR_CHANGINGCOUNT: return C_CHANGING;
    case VR_COUNTDOWNCOUNT: return C_COUNTDOWN;
    case VR_TRIGVALUE: case VR_TRIGSUM: case VR_TRIGCOUNT: return C_TRIGGER;
    case VR_OUTVALUE: return C_OUT;
    case VR_ALARMCOUNT: return C_ALARM;
    default: return -1;
    }
}

static void *create(fmi3String name, fmi3String token, int kind, fmi3InstanceEnvironment env,
                    fmi3LogMessageCallback logger) {
    Lab *m;
    if (!token || strcmp(token, TOKEN)) return NULL;
    m = (Lab *)new_instance(sizeof(Lab), name, kind, env, logger);
    if (!m) return NULL;
    m->uRate = 1.0;
    m->pFixedInterval = 0.3;
    m->pFixedShift = 0.2;
    m->pCountdown = 0.0;
    m->pThreshold = 0.35;
    m->pTimeEvent = -1.0;
    m->pFailAt = -1.0;
    for (int k = 0; k < N_CLOCKS; k++) m->next_due[k] = NAN, m->last_activation[k] = -INFINITY;
    m->interval[C_CONST] = 0.1;
    m->interval[C_FIXED] = 0.2, m->shift[C_FIXED] = 0.1;
    m->interval[C_TUNABLE] = 0.4, m->shift[C_TUNABLE] = 0.1;
    m->qualifier[C_COUNTDOWN] = Q_NOT_YET_KNOWN;
    m->se_time = -INFINITY;
    m->se_last_priority = -1;
    call_log(&m->b, "Instantiate kind=%d", kind);
    return m;
}

void fmi3FreeInstance(fmi3Instance inst) {
    Lab *m = (Lab *)inst;
    if (!m) return;
    if (m->b.state == S_FREED) { violation(&m->b, "fmi3FreeInstance twice"); return; }
    call_log(&m->b, "FreeInstance");
    m->b.state = S_FREED;
    free(m);
}

fmi3Status fmi3Reset(fmi3Instance inst) {
    (void)inst;
    return unsupported(inst, "fmi3Reset");
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance inst, fmi3Boolean tolDef, fmi3Float64 tol, fmi3Float64 start,
                                       fmi3Boolean stopDef, fmi3Float64 stop) {
    Lab *m = (Lab *)inst;
    (void)tolDef; (void)tol; (void)stopDef; (void)stop;
    if (!m || !in_states(&m->b, "fmi3EnterInitializationMode", M(S_INSTANTIATED))) return fmi3Error;
    call_log(&m->b, "EnterInitializationMode t=%g", start);
    m->b.time = start;
    m->b.state = S_INIT;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance inst) {
    Lab *m = (Lab *)inst;
    double t0;
    if (!m || !in_states(&m->b, "fmi3ExitInitializationMode", M(S_INIT))) return fmi3Error;
    call_log(&m->b, "ExitInitializationMode");
    if (!m->interval_set[C_FIXED]) return violation(&m->b, "cFixed (fixed, intervalDecimal) got no fmi3SetInterval in Initialization Mode");
    if (!m->interval_set[C_TUNABLE]) return violation(&m->b, "cTunable (tunable, intervalDecimal) got no fmi3SetInterval in Initialization Mode");
    if (!m->interval_read[C_FIXEDP] || !m->shift_read[C_FIXEDP])
        return violation(&m->b, "cFixedP (fixed, no intervalDecimal): its interval and shift were not asked in Initialization Mode");
    if (!m->interval_read[C_CHANGING]) return violation(&m->b, "cChanging: its first interval was not asked in Initialization Mode");
    if (!m->interval_read[C_COUNTDOWN]) return violation(&m->b, "cCountdown: its interval was not asked in Initialization Mode");
    t0 = m->b.time;
    m->interval[C_FIXEDP] = m->pFixedInterval;
    m->shift[C_FIXEDP] = m->pFixedShift;
    for (int k = 0; k <= C_TUNABLE; k++) m->next_due[k] = t0 + m->shift[k];
    m->b.state = m->b.kind == KIND_SE ? S_ACTIVATION : S_EVENT;
    m->countdown_read_after_uds = false;
    return fmi3OK;
}

/* ---------------------------------------------------------------- activations */
static void partition(Lab *m, int k) {
    double t = m->b.time;
    m->lastTime = t;
    m->ever[k] = true;
    if (periodic(k)) m->next_due[k] += m->interval[k];
    switch (k) {
    case C_CONST:
        m->constCount++;
        if (m->constCount % 3 == 0) m->out_pending[C_OUT] = m->active[C_OUT] = m->ever[C_OUT] = true;
        if (m->constCount % 4 == 0) {
            m->qualifier[C_COUNTDOWN] = Q_CHANGED;
            m->pending_interval[C_COUNTDOWN] = m->pCountdown;
            m->next_due[C_COUNTDOWN] = NAN;
        }
        if (m->b.kind == KIND_SE) m->yConstLast = 2 * m->uConst + m->constCount;
        break;
    case C_FIXED:
        m->fixedCount++;
        if (m->b.kind == KIND_SE) m->fixedValueLast = m->yConstLast + 1;
        break;
    case C_FIXEDP: m->fixedPCount++; break;
    case C_TUNABLE: m->tunableCount++; break;
    case C_CHANGING:
        m->changingCount++;
        m->qualifier[C_CHANGING] = Q_CHANGED;
        m->pending_interval[C_CHANGING] = 0.1 * (1 + m->changingCount % 3);
        m->next_due[C_CHANGING] = NAN;
        m->changing_unread = true;
        break;
    case C_COUNTDOWN:
        m->countdownCount++;
        m->qualifier[C_COUNTDOWN] = Q_NOT_YET_KNOWN;
        m->next_due[C_COUNTDOWN] = NAN;
        break;
    case C_TRIGGER:
        m->trigCount++;
        if (m->b.kind == KIND_SE) m->trigSumPrev += m->trigValue;
        else m->second_instant = true;
        break;
    }
}

/* a time-based clock activated at the FMU's time: is it due now? */
static fmi3Status check_due(Lab *m, int k) {
    double t = m->b.time;
    if (!time_based(k)) return fmi3OK;
    if (isnan(m->next_due[k])) return violation(&m->b, "%s activated at t = %.17g, but it is not due (no interval announced)", CLOCK[k], t);
    if (!near(t, m->next_due[k])) return violation(&m->b, "%s activated at t = %.17g, but it is due at %.17g", CLOCK[k], t, m->next_due[k]);
    return fmi3OK;
}

/* no time-based activation left behind before t (strictly) */
static fmi3Status check_missed(Lab *m, double t, const char *when) {
    for (int k = 0; k <= C_COUNTDOWN; k++)
        if (!isnan(m->next_due[k]) && m->next_due[k] < t - TOL * fmax(1.0, fabs(t)))
            return violation(&m->b, "%s was due at %.17g and not activated (%s at t = %.17g)", CLOCK[k], m->next_due[k], when, t);
    return fmi3OK;
}

fmi3Status fmi3SetClock(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, const fmi3Clock v[]) {
    Lab *m = (Lab *)inst;
    if (!m || !in_states(&m->b, "fmi3SetClock", M(S_EVENT))) {
        if (m && m->b.kind == KIND_SE) return fmi3Error;
        return fmi3Error;
    }
    for (size_t i = 0; i < n; i++) {
        int k = clock_of_vr(vr[i]);
        call_log(&m->b, "SetClock %s=%d t=%.17g", k >= 0 ? CLOCK[k] : "?", (int)v[i], m->b.time);
        if (!input_clock(k)) return violation(&m->b, "fmi3SetClock on value reference %u, not an input clock", vr[i]);
        if (!v[i]) return violation(&m->b, "fmi3SetClock(%s, inactive): it cannot be deactivated", CLOCK[k]);
        if (periodic(k) && m->activated_in_event[k]) return violation(&m->b, "periodic clock %s active twice in one Event Mode", CLOCK[k]);
        if (check_due(m, k) != fmi3OK) return fmi3Error;
        m->active[k] = m->activated_in_event[k] = true;
        partition(m, k);
    }
    return fmi3OK;
}

fmi3Status fmi3GetClock(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, fmi3Clock v[]) {
    Lab *m = (Lab *)inst;
    if (!m || !usable(&m->b, "fmi3GetClock")) return fmi3Error;
    if (m->b.kind == KIND_SE) {
        if (!m->in_callback) return violation(&m->b, "fmi3GetClock outside the clockUpdate callback (Scheduled Execution allows it only in Clock Update Mode)");
    } else if (m->b.state != S_EVENT) {
        return violation(&m->b, "fmi3GetClock in %s", STATE_NAME[m->b.state]);
    }
    for (size_t i = 0; i < n; i++) {
        int k = clock_of_vr(vr[i]);
        if (k != C_OUT && k != C_ALARM) return violation(&m->b, "fmi3GetClock on value reference %u, not an output clock", vr[i]);
        v[i] = m->out_pending[k];
        m->out_pending[k] = false;                     /* only the first read reports it */
        call_log(&m->b, "GetClock %s=%d t=%.17g", CLOCK[k], (int)v[i], m->b.time);
    }
    return fmi3OK;
}

/* ---------------------------------------------------------------- intervals */
static fmi3Status interval_of(Lab *m, int k, double *value, int *q) {
    bool init = m->b.state == S_INIT;
    switch (k) {
    case C_CONST: case C_FIXED: case C_TUNABLE:
        *value = m->interval[k]; *q = Q_UNCHANGED; return fmi3OK;
    case C_FIXEDP:
        *value = m->pFixedInterval;
        *q = (init && !m->interval_read[k]) ? Q_CHANGED : Q_UNCHANGED;
        m->interval_read[k] = true;
        return fmi3OK;
    case C_CHANGING:
        if (init) {
            *q = m->interval_read[k] ? Q_UNCHANGED : Q_CHANGED;
            *value = 0.1;
            if (*q == Q_CHANGED) m->next_due[k] = m->b.time + 0.1;
            m->interval_read[k] = true;
            return fmi3OK;
        }
        *q = m->qualifier[k];
        *value = m->pending_interval[k];
        if (*q == Q_CHANGED) { m->next_due[k] = m->b.time + *value; m->qualifier[k] = Q_UNCHANGED; }
        m->changing_unread = false;
        return fmi3OK;
    case C_COUNTDOWN:
        if (init) m->interval_read[k] = true;
        *q = m->qualifier[k];
        *value = m->pending_interval[k];
        if (*q == Q_CHANGED) { m->next_due[k] = m->b.time + *value; m->qualifier[k] = Q_UNCHANGED; }
        if (m->in_callback) m->countdown_read_in_callback = true;
        else m->countdown_read_after_uds = true;
        return fmi3OK;
    default:
        return violation(&m->b, "fmi3GetInterval of %s, which is not a time-based clock", k >= 0 ? CLOCK[k] : "?");
    }
}

static bool interval_state_ok(Lab *m, const char *fn) {
    if (!usable(&m->b, fn)) return false;
    if (m->b.state == S_INIT || m->b.state == S_EVENT || m->b.state == S_ACTIVATION || m->in_callback) return true;
    violation(&m->b, "%s in %s", fn, STATE_NAME[m->b.state]);
    return false;
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, fmi3Float64 iv[],
                                  fmi3IntervalQualifier q[]) {
    Lab *m = (Lab *)inst;
    if (!m || !interval_state_ok(m, "fmi3GetIntervalDecimal")) return fmi3Error;
    for (size_t i = 0; i < n; i++) {
        int k = clock_of_vr(vr[i]), qq = 0;
        double v = 0;
        if (interval_of(m, k, &v, &qq) != fmi3OK) return fmi3Error;
        iv[i] = v;
        q[i] = (fmi3IntervalQualifier)qq;
        call_log(&m->b, "GetIntervalDecimal %s -> %g q=%d t=%.17g", CLOCK[k], v, qq, m->b.time);
    }
    return fmi3OK;
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, fmi3UInt64 c[],
                                   fmi3UInt64 r[], fmi3IntervalQualifier q[]) {
    Lab *m = (Lab *)inst;
    if (!m || !interval_state_ok(m, "fmi3GetIntervalFraction")) return fmi3Error;
    for (size_t i = 0; i < n; i++) {
        int k = clock_of_vr(vr[i]), qq = 0;
        double v = 0;
        if (k < 0 || !FRACTION[k]) return violation(&m->b, "fmi3GetIntervalFraction of a clock without supportsFraction");
        if (interval_of(m, k, &v, &qq) != fmi3OK) return fmi3Error;
        r[i] = 10;
        c[i] = (fmi3UInt64)llround(v * 10);
        q[i] = (fmi3IntervalQualifier)qq;
        call_log(&m->b, "GetIntervalFraction %s -> %llu/10 q=%d", CLOCK[k], (unsigned long long)c[i], qq);
    }
    return fmi3OK;
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, const fmi3Float64 iv[]) {
    Lab *m = (Lab *)inst;
    if (!m || !usable(&m->b, "fmi3SetIntervalDecimal")) return fmi3Error;
    for (size_t i = 0; i < n; i++) {
        int k = clock_of_vr(vr[i]);
        call_log(&m->b, "SetIntervalDecimal %s=%.17g", k >= 0 ? CLOCK[k] : "?", iv[i]);
        if (k != C_FIXED && k != C_TUNABLE) return violation(&m->b, "fmi3SetIntervalDecimal of %s, whose interval the importer does not set", k >= 0 ? CLOCK[k] : "?");
        if (k == C_FIXED && m->b.state != S_INIT) return violation(&m->b, "fmi3SetIntervalDecimal of the fixed clock cFixed outside Initialization Mode");
        if (m->b.state != S_INIT && m->b.state != S_EVENT && m->b.state != S_ACTIVATION) return violation(&m->b, "fmi3SetIntervalDecimal in %s", STATE_NAME[m->b.state]);
        if (!(iv[i] > 0) || !isfinite(iv[i])) return violation(&m->b, "fmi3SetIntervalDecimal(%s, %g): an interval must be > 0", CLOCK[k], iv[i]);
        m->interval[k] = iv[i];
        m->interval_set[k] = true;
        if (k == C_FIXED) m->fixedSeen = iv[i];
    }
    return fmi3OK;
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 c[],
                                   const fmi3UInt64 r[]) {
    Lab *m = (Lab *)inst;
    if (!m || !usable(&m->b, "fmi3SetIntervalFraction")) return fmi3Error;
    for (size_t i = 0; i < n; i++) {
        int k = clock_of_vr(vr[i]);
        call_log(&m->b, "SetIntervalFraction %s=%llu/%llu", k >= 0 ? CLOCK[k] : "?", (unsigned long long)c[i], (unsigned long long)r[i]);
        if (k != C_TUNABLE) return violation(&m->b, "fmi3SetIntervalFraction of %s (only cTunable supports it here)", k >= 0 ? CLOCK[k] : "?");
        if (m->b.state != S_INIT && m->b.state != S_EVENT && m->b.state != S_ACTIVATION) return violation(&m->b, "fmi3SetIntervalFraction in %s", STATE_NAME[m->b.state]);
        if (!c[i] || !r[i]) return violation(&m->b, "fmi3SetIntervalFraction(%s, %llu/%llu): an interval must be > 0", CLOCK[k], (unsigned long long)c[i], (unsigned long long)r[i]);
        m->interval[k] = (double)c[i] / (double)r[i];
        m->interval_set[k] = true;
    }
    return fmi3OK;
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, fmi3Float64 s[]) {
    Lab *m = (Lab *)inst;
    if (!m || !interval_state_ok(m, "fmi3GetShiftDecimal")) return fmi3Error;
    for (size_t i = 0; i < n; i++) {
        int k = clock_of_vr(vr[i]);
        if (!periodic(k)) return violation(&m->b, "fmi3GetShiftDecimal of %s, not a periodic clock", k >= 0 ? CLOCK[k] : "?");
        s[i] = k == C_FIXEDP ? m->pFixedShift : m->shift[k];
        if (k == C_FIXEDP) m->shift_read[k] = true;
        call_log(&m->b, "GetShiftDecimal %s -> %g", CLOCK[k], s[i]);
    }
    return fmi3OK;
}

fmi3Status fmi3GetShiftFraction(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, fmi3UInt64 c[], fmi3UInt64 r[]) {
    Lab *m = (Lab *)inst;
    if (!m || !interval_state_ok(m, "fmi3GetShiftFraction")) return fmi3Error;
    for (size_t i = 0; i < n; i++) {
        int k = clock_of_vr(vr[i]);
        if (k < 0 || !FRACTION[k] || !periodic(k)) return violation(&m->b, "fmi3GetShiftFraction of a clock without supportsFraction");
        r[i] = 10;
        c[i] = (fmi3UInt64)llround(m->shift[k] * 10);
    }
    return fmi3OK;
}

/* ---------------------------------------------------------------- variables */
static bool clocked_access(Lab *m, fmi3ValueReference vr, bool set, const char *fn) {
    int k = clock_of_variable(vr);
    if (k < 0) return true;
    if (m->b.state == S_INSTANTIATED || m->b.state == S_INIT) return true;
    if (m->b.kind == KIND_SE) {
        if (set) return true;
        if (!m->ever[k]) { violation(&m->b, "%s of variable %u of %s before its partition ran", fn, vr, CLOCK[k]); return false; }
        return true;
    }
    if (m->b.state != S_EVENT || !m->active[k]) {
        violation(&m->b, "%s of variable %u, clocked by %s, while %s is not active (%s)", fn, vr, CLOCK[k], CLOCK[k], STATE_NAME[m->b.state]);
        return false;
    }
    return true;
}

static bool get_rules(Lab *m, const char *fn) {
    if (!usable(&m->b, fn)) return false;
    if (m->b.kind == KIND_CS && m->b.state == S_STEP && m->set_since_step) {
        violation(&m->b, "%s after a set in Step Mode without fmi3DoStep between", fn);
        return false;
    }
    if (m->b.kind == KIND_SE && m->b.state == S_ACTIVATION && m->set_since_activation) {
        violation(&m->b, "%s after a set without fmi3ActivateModelPartition between", fn);
        return false;
    }
    return true;
}

/* The instance of a getter (set false) or setter of the values of vr[n] (NULL after refusing
 * the call): a getter follows the get rules and each variable's clock; a setter checks each
 * variable's clock as it sets it. */
static Lab *value_call(fmi3Instance inst, const char *fn, bool set, const fmi3ValueReference vr[], size_t n, size_t nv) {
    Lab *m = (Lab *)inst;
    if (!m || !(set ? usable(&m->b, fn) : get_rules(m, fn)) || !scalars(&m->b, fn, n, nv)) return NULL;
    for (size_t i = 0; i < n && !set; i++)
        if (!clocked_access(m, vr[i], false, fn)) return NULL;
    return m;
}

/* The Float64 variable vr into *v; false if there is none. */
static bool float64_of(Lab *m, fmi3ValueReference vr, fmi3Float64 *v) {
    bool se = m->b.kind == KIND_SE, live = m->active[C_CONST] && !se;
    switch (vr) {
    case VR_TIME: *v = m->b.time; break;
    case VR_UCONST: *v = m->uConst; break;
    case VR_YCONST: *v = se ? m->yConstLast : 2 * m->uConst + m->constCount; break;
    case VR_TRIGVALUE: *v = m->trigValue; break;
    case VR_TRIGSUM: *v = se ? m->trigSumPrev : m->trigSumPrev + m->trigValue; break;
    case VR_OUTVALUE: *v = se ? m->yConstLast : (live ? 2 * m->uConst + m->constCount : m->outValueLast); break;
    case VR_X: *v = m->x; break;
    case VR_URATE: *v = m->uRate; break;
    case VR_LASTTIME: *v = m->lastTime; break;
    case VR_FIXEDSEEN: *v = m->fixedSeen; break;
    case VR_FIXEDVALUE: *v = se ? m->fixedValueLast : (live ? 2 * m->uConst + m->constCount : m->yConstLast) + 1; break;
    case VR_PFIXEDINTERVAL: *v = m->pFixedInterval; break;
    case VR_PFIXEDSHIFT: *v = m->pFixedShift; break;
    case VR_PCOUNTDOWN: *v = m->pCountdown; break;
    case VR_PTHRESHOLD: *v = m->pThreshold; break;
    case VR_PTIMEEVENT: *v = m->pTimeEvent; break;
    case VR_DERX: *v = m->uRate; break;
    case VR_Z: *v = m->pThreshold - m->x; break;
    case VR_PFAILAT: *v = m->pFailAt; break;
    default: return false;
    }
    return true;
}

/* The Int32 variable vr into *v; false if there is none. */
static bool int32_of(Lab *m, fmi3ValueReference vr, fmi3Int32 *v) {
    const int32_t *counts[] = {&m->constCount, &m->fixedCount, &m->fixedPCount, &m->tunableCount, &m->changingCount,
                               &m->countdownCount};      /* VR_CONSTCOUNT .. VR_COUNTDOWNCOUNT */
    if (vr >= VR_CONSTCOUNT && vr <= VR_COUNTDOWNCOUNT) *v = *counts[vr - VR_CONSTCOUNT];
    else if (vr == VR_TRIGCOUNT) *v = m->trigCount;
    else if (vr == VR_ALARMCOUNT) *v = m->alarmCount;
    else if (vr == VR_VIOLATIONS) *v = m->b.violations;
    else if (vr == VR_TIMEEVENTS) *v = m->timeEvents;
    else if (vr == VR_UMODE || vr == VR_MODESEEN) *v = m->uMode;
    else return false;
    return true;
}

#define GETTER(fn, T, value_of, what) fmi3Status fn(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, T v[], size_t nv) { \
    Lab *m = value_call(inst, #fn, false, vr, n, nv);                                                            \
    for (size_t i = 0; m && i < n; i++)                                                                          \
        if (!value_of(m, vr[i], &v[i])) return violation(&m->b, #fn " of value reference %u, not " what, vr[i]); \
    return m ? fmi3OK : fmi3Error; }
GETTER(fmi3GetFloat64, fmi3Float64, float64_of, "a Float64")
GETTER(fmi3GetInt32, fmi3Int32, int32_of, "an Int32")

fmi3Status fmi3SetFloat64(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, const fmi3Float64 v[], size_t nv) {
    Lab *m = value_call(inst, "fmi3SetFloat64", true, vr, n, nv);
    if (!m) return fmi3Error;
    for (size_t i = 0; i < n; i++) {
        bool param = (vr[i] >= VR_PFIXEDINTERVAL && vr[i] <= VR_PTIMEEVENT) || vr[i] == VR_PFAILAT;
        if (param && m->b.state != S_INSTANTIATED && m->b.state != S_INIT)
            return violation(&m->b, "fmi3SetFloat64 of the fixed parameter %u in %s", vr[i], STATE_NAME[m->b.state]);
        if (!clocked_access(m, vr[i], true, "fmi3SetFloat64")) return fmi3Error;
        switch (vr[i]) {
        case VR_UCONST: m->uConst = v[i]; break;
        case VR_TRIGVALUE: m->trigValue = v[i]; break;
        case VR_URATE:
            if (m->b.state == S_TERMINATED) return violation(&m->b, "fmi3SetFloat64 after fmi3Terminate");
            m->uRate = v[i];
            break;
        case VR_PFIXEDINTERVAL: m->pFixedInterval = v[i]; break;
        case VR_PFIXEDSHIFT: m->pFixedShift = v[i]; break;
        case VR_PCOUNTDOWN: m->pCountdown = v[i]; break;
        case VR_PTHRESHOLD: m->pThreshold = v[i]; break;
        case VR_PTIMEEVENT: m->pTimeEvent = v[i]; break;
        case VR_PFAILAT: m->pFailAt = v[i]; break;
        default: return violation(&m->b, "fmi3SetFloat64 of value reference %u, not a settable Float64", vr[i]);
        }
        call_log(&m->b, "SetFloat64 %u=%.17g t=%.17g", vr[i], v[i], m->b.time);
    }
    if (m->b.state == S_STEP) m->set_since_step = true;
    if (m->b.state == S_ACTIVATION) m->set_since_activation = true;
    return fmi3OK;
}

fmi3Status fmi3SetInt32(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, const fmi3Int32 v[], size_t nv) {
    Lab *m = value_call(inst, "fmi3SetInt32", true, vr, n, nv);
    if (!m) return fmi3Error;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != VR_UMODE) return violation(&m->b, "fmi3SetInt32 of value reference %u, not an Int32 input", vr[i]);
        if (m->b.state != S_INSTANTIATED && m->b.state != S_INIT && m->b.state != S_EVENT && m->b.state != S_ACTIVATION)
            return violation(&m->b, "fmi3SetInt32 of the discrete input uMode in %s (a discrete input changes in Event Mode)",
                             STATE_NAME[m->b.state]);
        m->uMode = v[i];
        call_log(&m->b, "SetInt32 uMode=%d t=%.17g", (int)v[i], m->b.time);
    }
    return fmi3OK;
}

/* pFailAt reached: an error, as an FMU that fails */
static bool requested_failure(Lab *m) {
    if (m->pFailAt < 0 || m->b.time < m->pFailAt - TOL) return false;
    m->pFailAt = -1.0;
    call_log(&m->b, "requested failure at t=%.17g", m->b.time);
    if (m->b.logger) m->b.logger(m->b.env, fmi3Error, "logStatusError", "requested failure (pFailAt)");
    m->b.state = S_ERROR;
    return true;
}

/* ---------------------------------------------------------------- Event Mode (ME, CS) */
static void state_event(Lab *m) {
    if (m->alarm_pending || (m->b.kind == KIND_ME && m->x >= m->pThreshold - 1e-12)) {
        m->alarm_pending = false;
        m->alarmCount++;
        m->active[C_ALARM] = m->out_pending[C_ALARM] = m->ever[C_ALARM] = true;
        m->x = 0.0;
    }
    if (m->pTimeEvent >= 0 && !m->time_event_done && near(m->b.time, m->pTimeEvent)) {
        m->time_event_done = true;
        m->timeEvents++;
    }
}

fmi3Status fmi3EnterEventMode(fmi3Instance inst) {
    Lab *m = (Lab *)inst;
    if (!m) return fmi3Error;
    if (m->b.kind == KIND_CS && !m->b.event_mode_used) return violation(&m->b, "fmi3EnterEventMode with eventModeUsed = false");
    if (!in_states(&m->b, "fmi3EnterEventMode", m->b.kind == KIND_ME ? M(S_CONT) : M(S_STEP))) return fmi3Error;
    call_log(&m->b, "EnterEventMode t=%.17g", m->b.time);
    if (check_missed(m, m->b.time, "fmi3EnterEventMode") != fmi3OK) return fmi3Error;
    m->b.state = S_EVENT;
    m->ehn_pending = false;
    for (int k = 0; k < N_CLOCKS; k++) m->activated_in_event[k] = false;
    m->countdown_read_after_uds = false;
    state_event(m);
    return fmi3OK;
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance inst, fmi3Boolean *need, fmi3Boolean *term, fmi3Boolean *nomc,
                                    fmi3Boolean *valc, fmi3Boolean *nextDef, fmi3Float64 *next) {
    Lab *m = (Lab *)inst;
    bool x_reset;
    if (!m || !in_states(&m->b, "fmi3UpdateDiscreteStates", M(S_EVENT))) return fmi3Error;
    call_log(&m->b, "UpdateDiscreteStates t=%.17g", m->b.time);
    if (requested_failure(m)) return fmi3Error;
    for (int k = C_OUT; k <= C_ALARM; k++)
        if (m->out_pending[k]) return violation(&m->b, "output clock %s ticked but was not read with fmi3GetClock before fmi3UpdateDiscreteStates", CLOCK[k]);
    x_reset = m->active[C_ALARM];
    if (m->active[C_CONST]) {
        m->yConstLast = 2 * m->uConst + m->constCount;
        if (m->active[C_OUT]) m->outValueLast = m->yConstLast;
    }
    if (m->active[C_FIXED]) m->fixedValueLast = m->yConstLast + 1;
    if (m->active[C_TRIGGER]) m->trigSumPrev += m->trigValue;
    for (int k = 0; k < N_CLOCKS; k++) m->active[k] = false;
    *need = m->second_instant;                 /* a trigger asks for one more super-dense instant */
    m->second_instant = false;
    *term = false;
    *nomc = false;
    *valc = x_reset;
    *nextDef = m->pTimeEvent > m->b.time + TOL && !m->time_event_done;
    *next = *nextDef ? m->pTimeEvent : 0.0;
    m->countdown_read_after_uds = false;
    return fmi3OK;
}

static fmi3Status leave_event_mode(Lab *m, const char *fn) {
    double t = m->b.time;
    for (int k = 0; k < N_CLOCKS; k++)
        if (m->active[k]) return violation(&m->b, "%s with %s still active (no fmi3UpdateDiscreteStates after it)", fn, CLOCK[k]);
    for (int k = 0; k <= C_COUNTDOWN; k++)
        if (!isnan(m->next_due[k]) && m->next_due[k] <= t + TOL * fmax(1.0, fabs(t)))
            return violation(&m->b, "%s at t = %.17g: %s was due at %.17g and not activated", fn, t, CLOCK[k], m->next_due[k]);
    if (!m->countdown_read_after_uds) return violation(&m->b, "%s: the countdown clock's interval was not read after the last fmi3UpdateDiscreteStates of this Event Mode", fn);
    if (m->changing_unread) return violation(&m->b, "%s: cChanging ticked but its next interval was not read", fn);
    return fmi3OK;
}

/* Event Mode left for the state `to` by fn, which only an instance of interface `kind` may call
 * (`wrong`: the violation of another). */
static fmi3Status leave_to(fmi3Instance inst, const char *fn, int kind, const char *wrong, int to) {
    Lab *m = (Lab *)inst;
    if (!m || m->b.kind != kind) return m ? violation(&m->b, "%s", wrong) : fmi3Error;
    if (!in_states(&m->b, fn, M(S_EVENT))) return fmi3Error;
    call_log(&m->b, "%s t=%.17g", fn + strlen("fmi3"), m->b.time);
    if (leave_event_mode(m, fn) != fmi3OK) return fmi3Error;
    m->b.state = to;
    m->set_since_step = false;
    return fmi3OK;
}

fmi3Status fmi3EnterStepMode(fmi3Instance inst) {
    return leave_to(inst, "fmi3EnterStepMode", KIND_CS, "fmi3EnterStepMode in Model Exchange", S_STEP);
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance inst) {
    return leave_to(inst, "fmi3EnterContinuousTimeMode", KIND_ME, "fmi3EnterContinuousTimeMode outside Model Exchange",
                    S_CONT);
}

/* ---------------------------------------------------------------- Co-Simulation */
fmi3Status fmi3DoStep(fmi3Instance inst, fmi3Float64 t, fmi3Float64 h, fmi3Boolean nsp, fmi3Boolean *ehn,
                      fmi3Boolean *term, fmi3Boolean *early, fmi3Float64 *last) {
    Lab *m = (Lab *)inst;
    double end, te;
    (void)nsp;
    if (!m || m->b.kind != KIND_CS) return m ? violation(&m->b, "fmi3DoStep outside Co-Simulation") : fmi3Error;
    if (m->ehn_pending) return violation(&m->b, "fmi3DoStep after eventHandlingNeeded without Event Mode between");
    if (!in_states(&m->b, "fmi3DoStep", M(S_STEP))) return fmi3Error;
    call_log(&m->b, "DoStep t=%.17g h=%.17g", t, h);
    if (!near(t, m->b.time)) return violation(&m->b, "fmi3DoStep at %.17g, but the FMU is at %.17g", t, m->b.time);
    if (!(h > 0)) return violation(&m->b, "fmi3DoStep with step %g (must be > 0)", h);
    end = t + h;
    for (int k = 0; k <= C_COUNTDOWN; k++) {
        double d = m->next_due[k];
        if (isnan(d)) continue;
        if (d <= t + TOL * fmax(1.0, fabs(t))) return violation(&m->b, "fmi3DoStep from t = %.17g: %s was due at %.17g and not activated", t, CLOCK[k], d);
        if (d < end - TOL * fmax(1.0, fabs(end))) return violation(&m->b, "fmi3DoStep(%.17g, %.17g) steps over the activation of %s at %.17g", t, h, CLOCK[k], d);
    }
    if (m->pTimeEvent >= 0 && !m->time_event_done && m->pTimeEvent > t + TOL && m->pTimeEvent < end - TOL)
        return violation(&m->b, "fmi3DoStep(%.17g, %.17g) steps over the time event at %.17g", t, h, m->pTimeEvent);
    m->set_since_step = false;
    *term = false;
    *ehn = false;
    *early = false;
    te = m->uRate > 0 ? t + (m->pThreshold - m->x) / m->uRate : INFINITY;
    if (te < end - TOL * fmax(1.0, fabs(end)) && m->b.early_return_allowed) {       /* return at the event */
        m->x = m->pThreshold;
        m->b.time = te;
        *early = true;
        *ehn = true;
        m->alarm_pending = true;
    } else {
        m->x += m->uRate * h;
        m->b.time = end;
        if (m->x >= m->pThreshold - 1e-12) { *ehn = true; m->alarm_pending = true; }
    }
    if (m->pTimeEvent >= 0 && !m->time_event_done && near(m->b.time, m->pTimeEvent)) *ehn = true;
    *last = m->b.time;
    m->ehn_pending = *ehn;
    if (*ehn) call_log(&m->b, "DoStep returns eventHandlingNeeded at %.17g (early=%d)", m->b.time, (int)*early);
    return fmi3OK;
}

/* ---------------------------------------------------------------- Model Exchange */
static size_t n_states(Base *b) { (void)b; return 1; }
static size_t n_indicators(Base *b) { (void)b; return 1; }
static void get_states(Base *b, double x[]) { x[0] = ((Lab *)b)->x; }
static void set_states(Base *b, const double x[]) { ((Lab *)b)->x = x[0]; }
static void derivatives(Base *b, double dx[]) { dx[0] = ((Lab *)b)->uRate; }
static void indicators(Base *b, double z[]) { z[0] = ((Lab *)b)->pThreshold - ((Lab *)b)->x; }

/* ---------------------------------------------------------------- Scheduled Execution */
fmi3Status fmi3ActivateModelPartition(fmi3Instance inst, fmi3ValueReference vr, fmi3Float64 t) {
    Lab *m = (Lab *)inst;
    int k = clock_of_vr(vr);
    bool announce, tick;
    if (!m || m->b.kind != KIND_SE) return m ? violation(&m->b, "fmi3ActivateModelPartition outside Scheduled Execution") : fmi3Error;
    if (!in_states(&m->b, "fmi3ActivateModelPartition", M(S_ACTIVATION))) return fmi3Error;
    call_log(&m->b, "ActivateModelPartition %s t=%.17g", k >= 0 ? CLOCK[k] : "?", t);
    if (!input_clock(k)) return violation(&m->b, "fmi3ActivateModelPartition of value reference %u, not an input clock", vr);
    if (!(t > m->last_activation[k])) return violation(&m->b, "%s activated at %.17g after an activation at %.17g (times must increase)", CLOCK[k], t, m->last_activation[k]);
    if (t < m->se_time) return violation(&m->b, "%s activated at %.17g, before an activation at %.17g", CLOCK[k], t, m->se_time);
    if (t > m->se_time) { m->se_time = t; m->se_last_priority = -1; }
    if (PRIORITY[k] < m->se_last_priority) return violation(&m->b, "%s (priority %d) activated at %.17g after a partition of priority %d", CLOCK[k], PRIORITY[k], t, m->se_last_priority);
    if (m->changing_unread) return violation(&m->b, "cChanging ticked but its next interval was not read before the next activation");
    m->se_last_priority = PRIORITY[k];
    m->last_activation[k] = t;
    m->b.time = t;
    if (check_missed(m, t, "fmi3ActivateModelPartition") != fmi3OK) return fmi3Error;
    if (check_due(m, k) != fmi3OK) return fmi3Error;
    m->set_since_activation = false;
    if (requested_failure(m)) return fmi3Error;
    partition(m, k);
    announce = m->qualifier[C_COUNTDOWN] == Q_CHANGED && k == C_CONST && m->constCount % 4 == 0;
    tick = m->out_pending[C_OUT];
    if (announce || tick) {
        m->in_callback = true;
        m->countdown_read_in_callback = false;
        call_log(&m->b, "clockUpdate t=%.17g", t);
        m->b.clock_update(m->b.env);
        m->in_callback = false;
        if (m->out_pending[C_OUT]) return violation(&m->b, "cOut ticked but the clockUpdate callback did not read it with fmi3GetClock");
        if (!m->countdown_read_in_callback) return violation(&m->b, "the clockUpdate callback did not read the countdown clock's interval");
    }
    return fmi3OK;
}

/* ---------------------------------------------------------------- the end */
fmi3Status fmi3Terminate(fmi3Instance inst) {
    Lab *m = (Lab *)inst;
    if (!m || !in_states(&m->b, "fmi3Terminate", M(S_EVENT) | M(S_CONT) | M(S_STEP) | M(S_ACTIVATION))) return fmi3Error;
    call_log(&m->b, "Terminate t=%.17g", m->b.time);
    if (check_missed(m, m->b.time, "fmi3Terminate") != fmi3OK) return fmi3Error;
    m->b.state = S_TERMINATED;
    return fmi3OK;
}

COMMON_STUBS
