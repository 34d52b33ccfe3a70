/* pendulum-cosim: error handling the FMI 2.0 and FMI 3.0 wrappers share.
 *
 * Include wrapper_modes.h first (the instance has a Mode), then this after defining: the status type STATUS with values STATUS_OK, STATUS_ERROR;
 * the instance type Instance (with fields `mode` and `char err[ERRLEN]`); and
 *   static void logmsg(Instance *c, STATUS st, const char *cat, const char *fn, const char *text);
 */
#ifndef WRAPPER_COMMON_H
#define WRAPPER_COMMON_H

#include <stdarg.h>
#include <stdio.h>
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

/* Status of a plant_core call that wrote its message into c->err. */
static STATUS core(Instance *c, const char *fn, int rc) {
    if (!rc) return STATUS_OK;
    logmsg(c, STATUS_ERROR, "logStatusError", fn, c->err);
    return STATUS_ERROR;
}

/* Start of every API function: the instance, and the modes the call is allowed in. */
#define ALLOW_IN(handle, fn, mask) Instance *c = (Instance *)(handle); \
    if (!c) return STATUS_ERROR; \
    if (!((1u << c->mode) & (mask))) return fail(c, fn, "not allowed in %s", mode_name(c->mode))

#endif
