/* pendulum-cosim: the state machine, error handling and FMU states the FMI 2.0 and FMI 3.0
 * wrappers share.
 *
 * Include wrapper_modes.h first, then this after defining: FMI_VERSION (2 or 3: FMI(Status) is
 * then fmi2Status or fmi3Status, FMI_NAME(Reset) "fmi2Reset" or "fmi3Reset"); the instance type
 * Instance (fields `mode`, `d` and `undo` (CoreData), `cats` (enabled log categories),
 * `char err[ERRLEN]` and the FMU-state registry `states`, `nstates`, `cap_states`); IS_CS(c),
 * true for a Co-Simulation (or Scheduled Execution) instance; optionally KIND_CODE(c) (0 Model
 * Exchange, 1 Co-Simulation, 2 Scheduled Execution; default from IS_CS) and CS_EXTRA_STATES
 * (states a Co-Simulation instance can also be in: Event Mode in the clocked form; default
 * none); and
 *   static void logmsg(Instance *c, STATUS st, const char *cat, const char *fn, const char *text);
 *   static void *mem_alloc(Instance *c, size_t size);   (zeroed memory or NULL)
 *   static void mem_free(Instance *c, void *p);
 *
 * Every FMI function names its instance argument `inst` and starts with ALLOW(fn, cs_mask,
 * me_mask): the states in which the standard allows it on a Co-Simulation and on a Model
 * Exchange instance (0: not part of that interface). Any other call is answered with Error and
 * a message naming the function and the state; every Error leaves the instance in M_ERROR.
 */
#ifndef WRAPPER_COMMON_H
#define WRAPPER_COMMON_H

#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include "wrapper_modes.h"

#define FMI_PASTE(v, name) fmi##v##name
#define FMI_EXPAND(v, name) FMI_PASTE(v, name)
#define FMI(name) FMI_EXPAND(FMI_VERSION, name)
#define FMI_STRING(v) #v
#define FMI_NAME_OF(v, name) "fmi" FMI_STRING(v) #name
#define FMI_NAME(name) FMI_NAME_OF(FMI_VERSION, name)

#define STATUS FMI(Status)
#define STATUS_OK FMI(OK)
#define STATUS_ERROR FMI(Error)
/* the functions allowed after an error (for the message) */
#define ERROR_CALLS FMI_NAME(FreeInstance) ", " FMI_NAME(Reset) ", " FMI_NAME(SetDebugLogging) \
    ", the FMU-state functions but the one that saves a state, and (values for debugging only) the getters"

/* Refuse a call: format the message into c->err, log it, enter the error state. */
static STATUS fail(Instance *c, const char *fn, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(c->err, sizeof c->err, fmt, ap);
    va_end(ap);
    logmsg(c, STATUS_ERROR, "logStatusError", fn, c->err);
    c->mode = M_ERROR;
    return STATUS_ERROR;
}

/* Status of a core call that wrote its message into c->err. */
static STATUS core(Instance *c, const char *fn, int rc) {
    if (!rc) return STATUS_OK;
    logmsg(c, STATUS_ERROR, "logStatusError", fn, c->err);
    c->mode = M_ERROR;
    return STATUS_ERROR;
}

/* A call that changes the core's data takes effect whole or not at all: BEGIN_CHANGE keeps
 * the data, undo() puts them back and refuses the call (a setter refused at its third value
 * leaves the first two unset; a doStep refused in its tenth update leaves the first nine
 * undone). */
#define BEGIN_CHANGE(c) memcpy(&(c)->undo, &(c)->d, sizeof (c)->d)
static STATUS undo(Instance *c, const char *fn) {
    memcpy(&c->d, &c->undo, sizeof c->d);
    return core(c, fn, 1);
}

#ifndef KIND_CODE
#define KIND_CODE(c) (IS_CS(c) ? 1 : 0)
#endif
#ifndef CS_EXTRA_STATES
#define CS_EXTRA_STATES 0u
#endif

/* The interface type of KIND_CODE `code`. */
static const char *kind_name(int code) {
    return code == 2 ? "Scheduled Execution" : code ? "Co-Simulation" : "Model Exchange";
}

/* The answer to a call in a state whose bit is not in `mask` (`other`: the mask of the other
 * interface type). */
static STATUS refuse_state(Instance *c, const char *fn, unsigned mask, unsigned other) {
    if (c->mode == M_ERROR)
        return fail(c, fn, "not allowed after a call returned Error: only %s may follow", ERROR_CALLS);
    if (!mask && other)
        return fail(c, fn, "a %s function, not allowed on this %s instance", kind_name(!IS_CS(c)),
                    kind_name(KIND_CODE(c)));
    return fail(c, fn, "not allowed in %s (%s instance)", mode_name(c->mode), kind_name(KIND_CODE(c)));
}

#define ALLOW(fn, cs_mask, me_mask) Instance *c = (Instance *)inst; \
    if (!c) return STATUS_ERROR; \
    do { unsigned m_ = IS_CS(c) ? (cs_mask) : (me_mask), o_ = IS_CS(c) ? (me_mask) : (cs_mask); \
         if (!(B(c->mode) & m_)) return refuse_state(c, fn, m_, o_); } while (0)

/* Arguments the standard requires: a pointer, an array of n > 0 elements. */
#define NOT_NULL(fn, p) do { if (!(p)) return fail(c, fn, "argument %s is NULL", #p); } while (0)
#define ARRAY(fn, p, n) do { if ((n) > 0 && !(p)) \
    return fail(c, fn, "argument %s is NULL but %s = %zu", #p, #n, (size_t)(n)); } while (0)

/* fmiXSetDebugLogging: the categories of the modelDescription, all of them for n = 0. */
static STATUS set_debug_logging(Instance *c, const char *fn, int on, size_t n, const char *const cats[]) {
    unsigned bits = n ? 0u : CAT_ALL_BITS;
    ARRAY(fn, cats, n);
    for (size_t i = 0; i < n; i++) {
        if (!cats[i]) return fail(c, fn, "categories[%zu] is NULL", i);
        if (!strcmp(cats[i], "logStatusError")) bits |= CAT_ERROR;
        else if (!strcmp(cats[i], "logAll")) bits |= CAT_ALL_BITS;
        else return fail(c, fn, "unknown log category \"%.60s\" (this FMU has logStatusError and logAll)", cats[i]);
    }
    c->cats = on ? (c->cats | bits) : (c->cats & ~bits);
    return STATUS_OK;
}

/* ------------------------------------------------------------------ FMU states
 * An FMU state holds the core's data and the instance's state-machine state, so that a state
 * saved while stepping can be restored into a fresh instance and stepped at once (fmusim's
 * --initial-fmu-state-file). It belongs to the instance that made it (GetFMUState or
 * DeserializeFMUState): each instance keeps the list of its states and refuses any other
 * pointer (a freed state, another instance's) without reading it; FreeInstance frees the
 * states left. Serialised as its bytes, with a checksum; deserialised bytes are checked
 * (size, checksum, interface type, state, every value of the core) before they are used. */
#define STATE_MAGIC 0x50435354u /* "PCST" */
#define MAX_STATES 100000u
typedef struct { unsigned magic; unsigned size; int mode; int cosim; uint64_t hash; CoreData d; } SavedState;

static uint64_t state_hash(const SavedState *s) {
    SavedState tmp;
    const unsigned char *b = (const unsigned char *)&tmp;
    uint64_t h = 0xcbf29ce484222325ull;            /* FNV-1a, 64 bit */
    memcpy(&tmp, s, sizeof tmp);
    tmp.hash = 0;
    for (size_t i = 0; i < sizeof tmp; i++) h = (h ^ b[i]) * 0x100000001b3ull;
    return h;
}

static int state_find(const Instance *c, const void *s) {
    for (size_t i = 0; i < c->nstates; i++)
        if (c->states[i] == s) return (int)i;
    return -1;
}

static SavedState *state_new(Instance *c, const char *fn) {
    SavedState *s;
    if (c->nstates == c->cap_states) {
        size_t cap = c->cap_states ? 2 * c->cap_states : 8;
        void **grown;
        if (c->nstates >= MAX_STATES) {
            fail(c, fn, "this instance already holds %zu FMU states: free some first", c->nstates);
            return NULL;
        }
        grown = (void **)mem_alloc(c, cap * sizeof(void *));
        if (!grown) { fail(c, fn, "out of memory"); return NULL; }
        if (c->nstates) memcpy(grown, c->states, c->nstates * sizeof(void *));
        if (c->states) mem_free(c, c->states);
        c->states = grown;
        c->cap_states = cap;
    }
    s = (SavedState *)mem_alloc(c, sizeof(SavedState));
    if (!s) { fail(c, fn, "out of memory"); return NULL; }
    c->states[c->nstates++] = s;
    return s;
}

static void states_free_all(Instance *c) {
    for (size_t i = 0; i < c->nstates; i++) mem_free(c, c->states[i]);
    if (c->states) mem_free(c, c->states);
    c->states = NULL;
    c->nstates = c->cap_states = 0;
}

/* An FMU state of this instance, or NULL after refusing the call. */
static SavedState *own_state(Instance *c, const char *fn, const void *s) {
    if (!s) { fail(c, fn, "the FMU state is NULL"); return NULL; }
    if (state_find(c, s) < 0) {
        fail(c, fn, "not an FMU state of this instance (freed, or made by another instance: "
                    "serialise it there and deserialise it here)");
        return NULL;
    }
    return (SavedState *)s;
}

/* 0 if s can be restored into c (message in c->err otherwise). */
static int check_state(const Instance *c, const SavedState *s, char *err) {
    /* no state is saved after an Error (FMI 2.0 2.1.3: a state got "in non-erroneous state";
     * FMI 3.0 2.2.4: after fmi3Error only fmi3SetFMUState, fmi3Reset or fmi3FreeInstance), so
     * restoring one restores the rules of the state it was saved in */
    int code = KIND_CODE(c);
    unsigned common = B(M_INSTANTIATED) | B(M_INIT) | B(M_TERMINATED);
    unsigned allowed = code == 2 ? common | B(M_ACTIVATION)
                     : code == 1 ? common | B(M_STEP) | CS_EXTRA_STATES : common | B(M_EVENT) | B(M_CONT);
    if (s->magic != STATE_MAGIC || s->size != sizeof(SavedState)) {
        snprintf(err, ERRLEN, "not an FMU state of this FMU");
        return 1;
    }
    if (s->cosim != code) {
        snprintf(err, ERRLEN, "a %s state cannot be restored into a %s instance",
                 s->cosim == 2 ? kind_name(2) : kind_name(s->cosim != 0), kind_name(code));
        return 1;
    }
    if (s->mode < 0 || s->mode > (int)M_ERROR || !(B(s->mode) & allowed)) {
        snprintf(err, ERRLEN, "the state holds an invalid instance state %d", s->mode);
        return 1;
    }
    return core_check(&s->d, err);
}

static void save_state(SavedState *s, const Instance *c) {
    memset(s, 0, sizeof *s);
    s->magic = STATE_MAGIC;
    s->size = sizeof(SavedState);
    s->mode = (int)c->mode;
    s->cosim = KIND_CODE(c);
    memcpy(&s->d, &c->d, sizeof s->d);
}

static STATUS get_fmu_state(Instance *c, const char *fn, void **s) {
    SavedState *st;
    NOT_NULL(fn, s);
    if (*s) {
        if (!(st = own_state(c, fn, *s))) return STATUS_ERROR;
    } else if (!(st = state_new(c, fn))) {
        return STATUS_ERROR;
    }
    save_state(st, c);
    *s = st;
    return STATUS_OK;
}

static STATUS set_fmu_state(Instance *c, const char *fn, const void *s) {
    const SavedState *st = own_state(c, fn, s);
    if (!st) return STATUS_ERROR;
    if (check_state(c, st, c->err)) return core(c, fn, 1);
    memcpy(&c->d, &st->d, sizeof c->d);
    c->mode = (Mode)st->mode;
    return STATUS_OK;
}

static STATUS free_fmu_state(Instance *c, const char *fn, void **s) {
    int i;
    if (!s || !*s) return STATUS_OK;               /* a NULL state: nothing to free */
    if ((i = state_find(c, *s)) < 0) return own_state(c, fn, *s) ? STATUS_OK : STATUS_ERROR;
    mem_free(c, c->states[i]);
    c->states[i] = c->states[--c->nstates];
    *s = NULL;
    return STATUS_OK;
}

static STATUS fmu_state_size(Instance *c, const char *fn, const void *s, size_t *size) {
    NOT_NULL(fn, size);
    if (!own_state(c, fn, s)) return STATUS_ERROR;
    *size = sizeof(SavedState);
    return STATUS_OK;
}

static STATUS serialize_fmu_state(Instance *c, const char *fn, const void *s, void *out, size_t size) {
    SavedState *st = own_state(c, fn, s);
    if (!st) return STATUS_ERROR;
    NOT_NULL(fn, out);
    if (size < sizeof(SavedState))
        return fail(c, fn, "buffer of %zu bytes, the serialised state needs %zu", size, sizeof(SavedState));
    st->hash = state_hash(st);
    memcpy(out, st, sizeof(SavedState));
    return STATUS_OK;
}

static STATUS deserialize_fmu_state(Instance *c, const char *fn, const void *in, size_t size, void **s) {
    SavedState tmp, *st;
    NOT_NULL(fn, in);
    NOT_NULL(fn, s);
    if (size != sizeof(SavedState))
        return fail(c, fn, "%zu bytes given, expected %zu (a serialised state of this FMU)", size, sizeof(SavedState));
    memcpy(&tmp, in, sizeof tmp);
    if (tmp.magic != STATE_MAGIC || tmp.size != sizeof(SavedState) || tmp.hash != state_hash(&tmp))
        return fail(c, fn, "the bytes are not a serialised state of this FMU (or were changed)");
    if (check_state(c, &tmp, c->err)) return core(c, fn, 1);
    if (*s) {
        if (!(st = own_state(c, fn, *s))) return STATUS_ERROR;
    } else if (!(st = state_new(c, fn))) {
        return STATUS_ERROR;
    }
    memcpy(st, &tmp, sizeof tmp);
    *s = st;
    return STATUS_OK;
}

#endif
