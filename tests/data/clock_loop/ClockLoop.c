/* ClockLoop: three hand-written FMI 3.0 test FMUs for a clocked control loop, one binary
 * (the role is chosen by the instantiation token of plant.xml, supervisor.xml or
 * controller.xml); independent of pendulum-cosim's code.
 *
 * plant       Model Exchange, no clocks: p' = v, v' = (u - c v - k p) / mass.
 * supervisor  Model Exchange: s' = p^2 (p an input); at the state event s = sLimit the
 *             output clock "alarm" ticks, "level" (clocked by it) = p, "alarms" counts,
 *             and s restarts from 0.
 * controller  Co-Simulation with Event Mode: the constant clock "sample" (every 0.01 s)
 *             samples y (clocked) and computes u = Kp (ref - y) - Kd (y - yPrev) / 0.01
 *             (clocked; no derivative term at the first sample); the triggered clock "mode" takes "level" (clocked), flips the sign
 *             of ref, and counts in "modes" (clocked); "ref" is not clocked.
 *
 * Each checks the clock call rules it receives as ../common/clock_base.h says:
 * clocks set only in Event Mode, "sample" exactly every 0.01 s (never early, late or
 * skipped, never stepped over), clocked variables exchanged only while their clock is
 * active, the output clock read before fmi3UpdateDiscreteStates, no clock left active when
 * Event Mode is left, fmi3DoStep only in Step Mode at the FMU's time. */
#define WITH_MODEL_EXCHANGE
#include "../common/clock_base.h"

enum { PLANT, SUPERVISOR, CONTROLLER };
static const char *TOKENS[] = {"{7a1e0c44-clockloop-plant-0001}", "{7a1e0c44-clockloop-supervisor-0001}",
                               "{7a1e0c44-clockloop-controller-0001}"};
#define SAMPLE 0.01

typedef struct {
    Base b;
    int role;
    /* plant */
    double p, v, u, k, c, mass;
    /* supervisor */
    double s, pin, sLimit, level;
    int32_t alarms;
    bool alarm_active, alarm_unread;
    /* controller */
    double y, uc, yPrev, ref, Kp, Kd, lvl, lastLevel, next_sample;
    int32_t modes;
    bool sample_active, mode_active, sampled_in_event, set_since_step, sampled_once;
} Loop;

static void *create(fmi3String name, fmi3String token, int kind, fmi3InstanceEnvironment env,
                    fmi3LogMessageCallback logger) {
    int role = -1;
    Loop *m;
    for (int r = 0; r < 3; r++)
        if (token && !strcmp(token, TOKENS[r])) role = r;
    if (role < 0) return NULL;
    if (kind == KIND_SE || (role == CONTROLLER) != (kind == KIND_CS)) return NULL;   /* plant, supervisor: ME only */
    m = (Loop *)new_instance(sizeof(Loop), name, kind, env, logger);
    if (!m) return NULL;
    m->role = role;
    m->k = 4.0, m->c = 0.4, m->mass = 1.0, m->p = 1.0;
    m->sLimit = 0.05;
    m->Kp = 3.0, m->Kd = 0.5, m->ref = 0.5;
    call_log(&m->b, "Instantiate role=%d", role);
    return m;
}

void fmi3FreeInstance(fmi3Instance inst) {
    Loop *m = (Loop *)inst;
    if (!m) return;
    call_log(&m->b, "FreeInstance");
    free(m);
}
fmi3Status fmi3Reset(fmi3Instance inst) { return unsupported(inst, "fmi3Reset"); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance inst, fmi3Boolean a, fmi3Float64 b, fmi3Float64 start,
                                       fmi3Boolean c, fmi3Float64 d) {
    Loop *m = (Loop *)inst;
    (void)a; (void)b; (void)c; (void)d;
    if (!m || !in_states(&m->b, "fmi3EnterInitializationMode", M(S_INSTANTIATED))) return fmi3Error;
    m->b.time = start;
    m->b.state = S_INIT;
    return fmi3OK;
}
fmi3Status fmi3ExitInitializationMode(fmi3Instance inst) {
    Loop *m = (Loop *)inst;
    if (!m || !in_states(&m->b, "fmi3ExitInitializationMode", M(S_INIT))) return fmi3Error;
    m->next_sample = m->b.time;
    m->b.state = S_EVENT;
    return fmi3OK;
}

/* ---------------------------------------------------------------- clocks */
fmi3Status fmi3SetClock(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, const fmi3Clock v[]) {
    Loop *m = (Loop *)inst;
    if (!m || !in_states(&m->b, "fmi3SetClock", M(S_EVENT))) return fmi3Error;
    if (m->role != CONTROLLER) return violation(&m->b, "fmi3SetClock: this FMU has no input clock");
    for (size_t i = 0; i < n; i++) {
        call_log(&m->b, "SetClock %u t=%.17g", vr[i], m->b.time);
        if (!v[i]) return violation(&m->b, "fmi3SetClock to inactive: the clocks cannot be deactivated");
        if (vr[i] == 1) {
            if (m->sampled_in_event) return violation(&m->b, "sample active twice in one Event Mode");
            if (!near(m->b.time, m->next_sample)) return violation(&m->b, "sample activated at %.17g, due at %.17g", m->b.time, m->next_sample);
            m->sample_active = m->sampled_in_event = true;
            m->next_sample += SAMPLE;
        } else if (vr[i] == 2) {
            m->mode_active = true;
            m->modes++;
        } else {
            return violation(&m->b, "fmi3SetClock on value reference %u, not an input clock", vr[i]);
        }
    }
    return fmi3OK;
}
fmi3Status fmi3GetClock(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, fmi3Clock v[]) {
    Loop *m = (Loop *)inst;
    if (!m || !in_states(&m->b, "fmi3GetClock", M(S_EVENT))) return fmi3Error;
    for (size_t i = 0; i < n; i++) {
        if (m->role != SUPERVISOR || vr[i] != 10) return violation(&m->b, "fmi3GetClock on value reference %u, not an output clock", vr[i]);
        v[i] = m->alarm_unread;
        m->alarm_unread = false;
        call_log(&m->b, "GetClock alarm=%d t=%.17g", (int)v[i], m->b.time);
    }
    return fmi3OK;
}
fmi3Status fmi3GetIntervalDecimal(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, fmi3Float64 iv[],
                                  fmi3IntervalQualifier q[]) {
    Loop *m = (Loop *)inst;
    if (!m || !usable(&m->b, "fmi3GetIntervalDecimal")) return fmi3Error;
    for (size_t i = 0; i < n; i++) {
        if (m->role != CONTROLLER || vr[i] != 1) return violation(&m->b, "fmi3GetIntervalDecimal of %u, not a time-based clock", vr[i]);
        iv[i] = SAMPLE;
        q[i] = fmi3IntervalUnchanged;
    }
    return fmi3OK;
}
DECIMAL_INTERVAL_STUBS

/* ---------------------------------------------------------------- variables
 * plant:      1 p (out)  2 v (out)  3 u (in, continuous)  4 k  5 c  6 mass (parameters)  7/8 der(p)/der(v)
 * supervisor: 10 alarm (output clock)  11 p (in, continuous)  12 s (out)  13 level (out, alarm)
 *             14 alarms (Int32 out, alarm)  15 sLimit (parameter)  16 der(s)  17 z (indicator)
 * controller: 1 sample  2 mode (clocks)  20 y (in, sample)  21 u (out, sample)  22 level (in, mode)
 *             23 lastLevel (out, mode)  24 modes (Int32 out, mode)  25 ref (out)  26 Kp  27 Kd */
static bool clock_ok(Loop *m, fmi3ValueReference vr, const char *fn) {
    int clock = 0;                          /* 1 sample, 2 mode, 10 alarm */
    if (m->role == CONTROLLER) clock = (vr == 20 || vr == 21) ? 1 : (vr >= 22 && vr <= 24) ? 2 : 0;
    if (m->role == SUPERVISOR) clock = (vr == 13 || vr == 14) ? 10 : 0;
    if (!clock || m->b.state == S_INSTANTIATED || m->b.state == S_INIT) return true;
    bool active = m->b.state == S_EVENT && (clock == 1 ? m->sample_active : clock == 2 ? m->mode_active : m->alarm_active);
    if (!active) violation(&m->b, "%s of variable %u while its clock %d is not active (%s)", fn, vr, clock, STATE_NAME[m->b.state]);
    return active;
}

fmi3Status fmi3GetFloat64(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, fmi3Float64 v[], size_t nv) {
    Loop *m = (Loop *)inst;
    if (!m || !usable(&m->b, "fmi3GetFloat64") || !scalars(&m->b, "fmi3GetFloat64", n, nv)) return fmi3Error;
    if (m->role == CONTROLLER && m->b.state == S_STEP && m->set_since_step)
        return violation(&m->b, "fmi3GetFloat64 after a set in Step Mode without fmi3DoStep between");
    for (size_t i = 0; i < n; i++) {
        if (!clock_ok(m, vr[i], "fmi3GetFloat64")) return fmi3Error;
        if (vr[i] == 0) { v[i] = m->b.time; continue; }
        switch (m->role * 100 + (int)vr[i]) {
        case PLANT * 100 + 1: v[i] = m->p; break;
        case PLANT * 100 + 2: v[i] = m->v; break;
        case PLANT * 100 + 3: v[i] = m->u; break;
        case PLANT * 100 + 4: v[i] = m->k; break;
        case PLANT * 100 + 5: v[i] = m->c; break;
        case PLANT * 100 + 6: v[i] = m->mass; break;
        case PLANT * 100 + 7: v[i] = m->v; break;
        case PLANT * 100 + 8: v[i] = (m->u - m->c * m->v - m->k * m->p) / m->mass; break;
        case SUPERVISOR * 100 + 11: v[i] = m->pin; break;
        case SUPERVISOR * 100 + 12: v[i] = m->s; break;
        case SUPERVISOR * 100 + 13: v[i] = m->level; break;
        case SUPERVISOR * 100 + 15: v[i] = m->sLimit; break;
        case SUPERVISOR * 100 + 16: v[i] = m->pin * m->pin; break;
        case SUPERVISOR * 100 + 17: v[i] = m->sLimit - m->s; break;
        case CONTROLLER * 100 + 20: v[i] = m->y; break;
        case CONTROLLER * 100 + 21:
            v[i] = m->Kp * (m->ref - m->y) - (m->sampled_once ? m->Kd * (m->y - m->yPrev) / SAMPLE : 0.0);
            break;
        case CONTROLLER * 100 + 22: v[i] = m->lvl; break;
        case CONTROLLER * 100 + 23: v[i] = m->lvl; break;
        case CONTROLLER * 100 + 25: v[i] = m->ref; break;
        case CONTROLLER * 100 + 26: v[i] = m->Kp; break;
        case CONTROLLER * 100 + 27: v[i] = m->Kd; break;
        default: return violation(&m->b, "fmi3GetFloat64 of value reference %u, not a Float64 here", vr[i]);
        }
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, const fmi3Float64 v[], size_t nv) {
    Loop *m = (Loop *)inst;
    if (!m || !usable(&m->b, "fmi3SetFloat64")) return fmi3Error;
    if (!scalars(&m->b, "fmi3SetFloat64", n, nv)) return fmi3Error;
    for (size_t i = 0; i < n; i++) {
        int key = m->role * 100 + (int)vr[i];
        bool param = key == PLANT * 100 + 4 || key == PLANT * 100 + 5 || key == PLANT * 100 + 6 ||
                     key == SUPERVISOR * 100 + 15 || key == CONTROLLER * 100 + 26 || key == CONTROLLER * 100 + 27;
        if (param && m->b.state != S_INSTANTIATED && m->b.state != S_INIT)
            return violation(&m->b, "fmi3SetFloat64 of parameter %u in %s", vr[i], STATE_NAME[m->b.state]);
        if (!clock_ok(m, vr[i], "fmi3SetFloat64")) return fmi3Error;
        if (!isfinite(v[i])) return violation(&m->b, "fmi3SetFloat64(%u, %g): not finite", vr[i], v[i]);
        switch (key) {
        case PLANT * 100 + 3: m->u = v[i]; break;
        case PLANT * 100 + 4: m->k = v[i]; break;
        case PLANT * 100 + 5: m->c = v[i]; break;
        case PLANT * 100 + 6:
            if (!(v[i] > 0)) return violation(&m->b, "mass must be > 0");
            m->mass = v[i];
            break;
        case SUPERVISOR * 100 + 11: m->pin = v[i]; break;
        case SUPERVISOR * 100 + 15: m->sLimit = v[i]; break;
        case CONTROLLER * 100 + 20: m->y = v[i]; break;
        case CONTROLLER * 100 + 22: m->lvl = v[i]; break;
        case CONTROLLER * 100 + 26: m->Kp = v[i]; break;
        case CONTROLLER * 100 + 27: m->Kd = v[i]; break;
        default: return violation(&m->b, "fmi3SetFloat64 of value reference %u, not settable here", vr[i]);
        }
        call_log(&m->b, "SetFloat64 %u=%.17g t=%.17g", vr[i], v[i], m->b.time);
    }
    if (m->b.state == S_STEP) m->set_since_step = true;
    return fmi3OK;
}

fmi3Status fmi3GetInt32(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, fmi3Int32 v[], size_t nv) {
    Loop *m = (Loop *)inst;
    if (!m || !usable(&m->b, "fmi3GetInt32")) return fmi3Error;
    if (!scalars(&m->b, "fmi3GetInt32", n, nv)) return fmi3Error;
    for (size_t i = 0; i < n; i++) {
        if (!clock_ok(m, vr[i], "fmi3GetInt32")) return fmi3Error;
        if (m->role == SUPERVISOR && vr[i] == 14) v[i] = m->alarms;
        else if (m->role == CONTROLLER && vr[i] == 24) v[i] = m->modes;
        else if (vr[i] == 99) v[i] = m->b.violations;
        else return violation(&m->b, "fmi3GetInt32 of value reference %u, not an Int32 here", vr[i]);
    }
    return fmi3OK;
}
fmi3Status fmi3SetInt32(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, const fmi3Int32 v[], size_t nv) {
    (void)vr; (void)n; (void)v; (void)nv; return unsupported(inst, "fmi3SetInt32"); }

/* ---------------------------------------------------------------- events */
fmi3Status fmi3EnterEventMode(fmi3Instance inst) {
    Loop *m = (Loop *)inst;
    if (!m) return fmi3Error;
    if (!in_states(&m->b, "fmi3EnterEventMode", m->role == CONTROLLER ? M(S_STEP) : M(S_CONT))) return fmi3Error;
    call_log(&m->b, "EnterEventMode t=%.17g", m->b.time);
    if (m->role == CONTROLLER && m->next_sample < m->b.time - TOL)
        return violation(&m->b, "sample was due at %.17g and not activated (now %.17g)", m->next_sample, m->b.time);
    m->b.state = S_EVENT;
    m->sampled_in_event = false;
    if (m->role == SUPERVISOR && m->s >= m->sLimit - 1e-12) {       /* the state event */
        m->alarm_active = m->alarm_unread = true;
        m->alarms++;
        m->level = m->pin;
        m->s = 0.0;
    }
    return fmi3OK;
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance inst, fmi3Boolean *need, fmi3Boolean *term, fmi3Boolean *nomc,
                                    fmi3Boolean *valc, fmi3Boolean *nextDef, fmi3Float64 *next) {
    Loop *m = (Loop *)inst;
    if (!m || !in_states(&m->b, "fmi3UpdateDiscreteStates", M(S_EVENT))) return fmi3Error;
    call_log(&m->b, "UpdateDiscreteStates t=%.17g", m->b.time);
    if (m->alarm_unread) return violation(&m->b, "alarm ticked but was not read with fmi3GetClock before fmi3UpdateDiscreteStates");
    *valc = m->alarm_active;
    if (m->sample_active) m->yPrev = m->y, m->sampled_once = true;
    if (m->mode_active) { m->ref = -m->ref; m->lastLevel = m->lvl; }
    m->sample_active = m->mode_active = m->alarm_active = false;
    *need = *term = *nomc = *nextDef = false;
    *next = 0;
    return fmi3OK;
}

static fmi3Status leave(Loop *m, const char *fn) {
    if (m->sample_active || m->mode_active || m->alarm_active)
        return violation(&m->b, "%s with a clock still active (no fmi3UpdateDiscreteStates after it)", fn);
    if (m->role == CONTROLLER && m->next_sample <= m->b.time + TOL)
        return violation(&m->b, "%s at %.17g: sample was due at %.17g and not activated", fn, m->b.time, m->next_sample);
    return fmi3OK;
}
fmi3Status fmi3EnterStepMode(fmi3Instance inst) {
    Loop *m = (Loop *)inst;
    if (!m || !in_states(&m->b, "fmi3EnterStepMode", M(S_EVENT)) || leave(m, "fmi3EnterStepMode")) return fmi3Error;
    m->b.state = S_STEP;
    m->set_since_step = false;
    return fmi3OK;
}
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance inst) {
    Loop *m = (Loop *)inst;
    if (!m || !in_states(&m->b, "fmi3EnterContinuousTimeMode", M(S_EVENT)) || leave(m, "fmi3EnterContinuousTimeMode")) return fmi3Error;
    m->b.state = S_CONT;
    return fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance inst, fmi3Float64 t, fmi3Float64 h, fmi3Boolean nsp, fmi3Boolean *ehn,
                      fmi3Boolean *term, fmi3Boolean *early, fmi3Float64 *last) {
    Loop *m = (Loop *)inst;
    (void)nsp;
    if (!m || !in_states(&m->b, "fmi3DoStep", M(S_STEP))) return fmi3Error;
    call_log(&m->b, "DoStep t=%.17g h=%.17g", t, h);
    if (!near(t, m->b.time)) return violation(&m->b, "fmi3DoStep at %.17g, but the FMU is at %.17g", t, m->b.time);
    if (!(h > 0)) return violation(&m->b, "fmi3DoStep with step %g", h);
    if (m->next_sample < t + h - TOL) return violation(&m->b, "fmi3DoStep(%.17g, %.17g) steps over the sample at %.17g", t, h, m->next_sample);
    m->b.time = t + h;
    m->set_since_step = false;
    *ehn = *term = *early = false;
    *last = m->b.time;
    return fmi3OK;
}

/* ---------------------------------------------------------------- Model Exchange */
static size_t n_states(Base *b) { Loop *m = (Loop *)b; return m->role == PLANT ? 2 : m->role == SUPERVISOR ? 1 : 0; }
static size_t n_indicators(Base *b) { return ((Loop *)b)->role == SUPERVISOR; }
static void get_states(Base *b, double x[]) {
    Loop *m = (Loop *)b;
    if (m->role == PLANT) x[0] = m->p, x[1] = m->v;
    else x[0] = m->s;
}
static void set_states(Base *b, const double x[]) {
    Loop *m = (Loop *)b;
    if (m->role == PLANT) m->p = x[0], m->v = x[1];
    else m->s = x[0];
}
static void derivatives(Base *b, double dx[]) {
    Loop *m = (Loop *)b;
    if (m->role == PLANT) dx[0] = m->v, dx[1] = (m->u - m->c * m->v - m->k * m->p) / m->mass;
    else dx[0] = m->pin * m->pin;
}
static void indicators(Base *b, double z[]) {
    Loop *m = (Loop *)b;
    if (m->role == SUPERVISOR) z[0] = m->sLimit - m->s;
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance inst, fmi3ValueReference vr, fmi3Float64 t) {
    (void)vr; (void)t; return unsupported(inst, "fmi3ActivateModelPartition"); }

fmi3Status fmi3Terminate(fmi3Instance inst) {
    Loop *m = (Loop *)inst;
    if (!m || !in_states(&m->b, "fmi3Terminate", M(S_EVENT) | M(S_CONT) | M(S_STEP))) return fmi3Error;
    if (m->role == CONTROLLER && m->next_sample < m->b.time - TOL)
        return violation(&m->b, "sample was due at %.17g and not activated (fmi3Terminate at %.17g)", m->next_sample, m->b.time);
    m->b.state = S_TERMINATED;
    return fmi3OK;
}

COMMON_STUBS
