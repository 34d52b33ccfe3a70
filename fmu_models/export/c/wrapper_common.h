/* pendulum-cosim: error handling and FMU state the FMI 2.0 and FMI 3.0 wrappers share.
 *
 * Include wrapper_modes.h first (the instance has a Mode), then this after defining: the status
 * type STATUS with values STATUS_OK, STATUS_ERROR; the instance type Instance (with fields
 * `mode`, `d` (CoreData) and `char err[ERRLEN]`); IS_CS(c), true for a Co-Simulation instance;
 * and
 *   static void logmsg(Instance *c, STATUS st, const char *cat, const char *fn, const char *text);
 */
#ifndef WRAPPER_COMMON_H
#define WRAPPER_COMMON_H

#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include "wrapper_modes.h"

/* Refuse a call: format the message into c->err, log it, return an error status. */
static STATUS fail(Instance *c, const char *fn, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(c->err, sizeof c->err, fmt, ap);
    va_end(ap);
    logmsg(c, STATUS_ERROR, "logStatusError", fn, c->err);
    return STATUS_ERROR;
}

/* Status of a core call that wrote its message into c->err. */
static STATUS core(Instance *c, const char *fn, int rc) {
    if (!rc) return STATUS_OK;
    logmsg(c, STATUS_ERROR, "logStatusError", fn, c->err);
    return STATUS_ERROR;
}

/* Start of every API function: the instance, and the modes the call is allowed in. */
#define ALLOW_IN(handle, fn, mask) Instance *c = (Instance *)(handle); \
    if (!c) return STATUS_ERROR; \
    if (!((1u << c->mode) & (mask))) return fail(c, fn, "not allowed in %s", mode_name(c->mode))

/* The FMU state: the core's data and the instance's mode, so that a state saved while
 * stepping can be restored into a fresh instance and stepped at once (fmusim's
 * --initial-fmu-state-file). Serialised as its bytes. */
#define STATE_MAGIC 0x50435354u /* "PCST" */
typedef struct { unsigned magic; unsigned size; int mode; int cosim; CoreData d; } SavedState;

static void save_state(SavedState *s, const Instance *c) {
    s->magic = STATE_MAGIC;
    s->size = sizeof(SavedState);
    s->mode = (int)c->mode;
    s->cosim = IS_CS(c) ? 1 : 0;
    s->d = c->d;
}

static STATUS restore_state(Instance *c, const char *fn, const SavedState *s) {
    if (!s || s->magic != STATE_MAGIC || s->size != sizeof(SavedState))
        return fail(c, fn, "not an FMU state of this FMU");
    if (s->cosim != (IS_CS(c) ? 1 : 0))
        return fail(c, fn, "a %s state cannot be restored into a %s instance",
                    s->cosim ? "Co-Simulation" : "Model Exchange", IS_CS(c) ? "Co-Simulation" : "Model Exchange");
    if (s->mode < M_INSTANTIATED || s->mode > M_TERMINATED)
        return fail(c, fn, "the state holds an invalid mode %d", s->mode);
    c->d = s->d;
    c->mode = (Mode)s->mode;
    return STATUS_OK;
}

static int deserialize_state(const unsigned char *bytes, size_t size, SavedState *out, char *err) {
    if (size != sizeof(SavedState)) {
        snprintf(err, ERRLEN, "%zu bytes given, expected %zu", size, sizeof(SavedState));
        return 1;
    }
    memcpy(out, bytes, sizeof(SavedState));
    if (out->magic != STATE_MAGIC || out->size != sizeof(SavedState)) {
        snprintf(err, ERRLEN, "bytes are not a serialised state of this FMU");
        return 1;
    }
    return 0;
}

#endif
