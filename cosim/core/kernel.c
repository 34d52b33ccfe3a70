/* The co-simulation master's base-step loop in C (see cosim/core/native.py).
 *
 * One generic interpreter, compiled once and cached: the master prepares, per pattern of
 * due components, a program of operations (set inputs by value reference from the signal
 * buffer, doStep, get outputs, a filter's compiled step, a source's value, a call back into
 * Python) and the kernel runs base steps until something needs Python: a Python
 * component's call, a full record buffer, a failed call, a non-finite signal at the end of
 * a block of steps, or the end of the chunk of steps it was given. Its state is kept in
 * kstate_t, so every return can be resumed.
 *
 * Arithmetic is the Python path's, operation for operation (t = t0 + k * h, the same
 * comparisons): compiled with -ffp-contract=off so that no multiply-add is fused.
 */
#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

typedef int (*fmi2_xfer_t)(void *, const unsigned int *, size_t, double *);   /* FMI 1.0's too */
typedef int (*fmi3_xfer_t)(void *, const unsigned int *, size_t, double *, size_t);
typedef int (*fmi1_step_t)(void *, double, double, char);
typedef int (*fmi2_step_t)(void *, double, double, int);
typedef int (*fmi3_step_t)(void *, double, double, bool, bool *, bool *, bool *, double *);
typedef int (*casadi_fn_t)(const double **, double **, long long *, double *, int);

enum {
    OP_PY = 0,       /* a Python callable: return to Python */
    OP_GET = 1,      /* FMI get (Real / Float64), then scatter into the signals */
    OP_SET = 2,      /* gather from the signals, then FMI set (Real / Float64) */
    OP_STEP2 = 3,    /* fmi2DoStep(t, h, true) */
    OP_STEP3 = 4,    /* fmi3DoStep(t, h, true, ...) */
    OP_CONST = 5,    /* values[slot] = a */
    OP_SWITCH = 6,   /* values[slot] = t >= a ? c : b */
    OP_FILTER = 7,   /* a filter's output: its compiled step (after its first instant) */
    OP_HOLD = 8,     /* a filter's update: keep the inputs for the next step */
    OP_HOOK = 9,     /* after a filter's step: its Python hook (if the flag buf[0] is set; no flag: always) */
    OP_SUMMARY = 10, /* a filter's outputs: estimate, covariance entries, NIS */
    OP_NOISE = 11,   /* a noise stream's row of the instant (a new instant: the next row); flag: a sensor */
    OP_PRBS = 12,    /* values[slot] = b + (bits[floor(t / a + 1e-9) mod n] ? c : -c) */
    OP_RECORD = 13,  /* after a filter's step that adapted (flag buf[0]): a row of its noise history */
    OP_STEP1 = 14    /* FMI 1.0 fmiDoStep(t, h, newStep = fmiTrue) */
};

enum {
    EV_DONE = 0,      /* every step ran */
    EV_PY = 1,        /* run the Python callable of op pc, then resume at pc + 1 */
    EV_FAIL = 2,      /* op pc failed (status in the op's result fields) */
    EV_FLUSH = 3,     /* the record buffer is full: flush it, set j = 0, resume */
    EV_NONFINITE = 4, /* a non-finite value at the end of the block that began at k0 */
    EV_CHUNK = 5,     /* the chunk of steps is done (at a block boundary) */
    EV_HOOK = 6,      /* run the Python hook of op pc, then resume at pc + 1 */
    EV_REFILL = 7     /* op pc's noise stream has no row left: refill it, then resume at pc */
};

typedef struct {
    int64_t kind;
    int64_t owner;        /* index of the Python callable this op belongs to (in its phase) */
    int64_t n;            /* entries of idx / off */
    int64_t nvr;          /* value references */
    int64_t nbuf;         /* values moved by the FMI call (FMI 3.0 nValues) */
    int64_t status;       /* result: the failing status */
    int64_t flag;         /* result: terminateSimulation (FMI 3.0) */
    int64_t slot;         /* signal written by a source */
    void *fn;             /* the FMI or CasADi function */
    void *inst;           /* the FMU instance */
    const unsigned int *vr;
    double *buf;          /* the FMU side of a get / set */
    const int64_t *idx;   /* signal positions */
    const int64_t *off;   /* positions in buf */
    double a, b, c, d;    /* source parameters; d: FMI 3.0 lastSuccessfulTime */
    /* filter */
    const double **arg[2]; /* arguments from state copy 0 / 1 */
    double **res[2];
    long long *iw;
    double *w;
    double *ub, *yb;      /* the step's u and y inputs */
    double *uprev;        /* the input held from the previous instant */
    const int64_t *yidx;  /* measurement signals */
    int64_t ny, nu, nx, nup; /* nup: upper covariance entries in the summary */
    int64_t *cur;         /* [0]: current state copy, [1]: step count, [2]: started, [3]: stepped now */
    const double *status_out; /* the step's status output */
    const double *x[2], *P[2]; const double *nis;
    double *out;          /* summary destination (values + first output) */
    const int64_t *uidx;  /* input signals held by the update */
    const int64_t *upi, *upj; /* upper covariance entries */
} op_t;

typedef struct {
    /* fixed for the run */
    double t0, h;
    int64_t n, m, L, cap, ncols, nint, nsig, block;
    double *values;
    int64_t *integers;
    double *buf;          /* record rows: cap x ncols */
    int64_t *ibuf;        /* integer record rows: cap x nint */
    const int64_t *sel;   /* recorded signals */
    const int64_t *isel;  /* recorded integer signals */
    const int64_t *pattern;   /* k % L -> pattern */
    const int64_t *out_start, *out_len, *upd_start, *upd_len; /* per pattern, into ops */
    op_t *ops;
    /* resumable state */
    int64_t k, phase, pc, j, jb, k0, kstop;
    int64_t at;           /* the op an EV_PY / EV_FAIL event is about (index into ops) */
} kstate_t;

static int finite_rows(const double *buf, int64_t ncols, int64_t lo, int64_t hi) {
    for (int64_t i = lo * ncols; i < hi * ncols; i++)
        if (!isfinite(buf[i])) return 0;
    return 1;
}

static int block_finite(kstate_t *s) {
    for (int64_t i = 0; i < s->nsig; i++)
        if (!isfinite(s->values[i])) return 0;
    if (s->j >= s->jb) return finite_rows(s->buf, s->ncols, s->jb, s->j);
    return finite_rows(s->buf, s->ncols, s->jb, s->cap) && finite_rows(s->buf, s->ncols, 0, s->j);
}

/* The FMI get or set of op (FMI 2.0 Real or, with its nValues nbuf >= 0, FMI 3.0 Float64):
 * its status. */
static int transfer(op_t *o) {
    return o->nbuf < 0 ? ((fmi2_xfer_t)o->fn)(o->inst, o->vr, (size_t)o->nvr, o->buf)
                       : ((fmi3_xfer_t)o->fn)(o->inst, o->vr, (size_t)o->nvr, o->buf, (size_t)o->nbuf);
}

/* Run op; 0: go on, else the event. */
static int run_op(kstate_t *s, op_t *o, double t) {
    double *v = s->values;
    int st;
    switch (o->kind) {
    case OP_PY:
        return EV_PY;
    case OP_GET:
        st = transfer(o);
        if (st > 1) { o->status = st; return EV_FAIL; }
        for (int64_t i = 0; i < o->n; i++) v[o->idx[i]] = o->buf[o->off[i]];
        return 0;
    case OP_SET:
        for (int64_t i = 0; i < o->n; i++) o->buf[o->off[i]] = v[o->idx[i]];
        st = transfer(o);
        if (st > 1) { o->status = st; return EV_FAIL; }
        return 0;
    case OP_STEP1:
        st = ((fmi1_step_t)o->fn)(o->inst, t, o->a, 1);
        if (st > 1) { o->status = st; return EV_FAIL; }
        return 0;
    case OP_STEP2:
        st = ((fmi2_step_t)o->fn)(o->inst, t, o->a, 1);
        if (st > 1) { o->status = st; return EV_FAIL; }
        return 0;
    case OP_STEP3: {
        bool ev = false, term = false, early = false;
        double last = 0.0;
        st = ((fmi3_step_t)o->fn)(o->inst, t, o->a, true, &ev, &term, &early, &last);
        if (st > 1 || term) { o->status = st; o->flag = term; o->d = last; return EV_FAIL; }
        return 0;
    }
    case OP_CONST:
        v[o->slot] = o->a;
        return 0;
    case OP_SWITCH:
        v[o->slot] = t >= o->a ? o->c : o->b;
        return 0;
    case OP_FILTER: {
        int64_t c = o->cur[0];
        o->cur[3] = 0;
        if (o->cur[2]) {
            for (int64_t i = 0; i < o->nu; i++) o->ub[i] = o->uprev[i];
            for (int64_t i = 0; i < o->ny; i++) o->yb[i] = v[o->yidx[i]];
            ((casadi_fn_t)o->fn)(o->arg[c], o->res[c], o->iw, o->w, 0);
            if (o->status_out[0] != 0.0) { o->status = 1; return EV_FAIL; }
            c ^= 1;
            o->cur[0] = c;
            o->cur[1] += 1;
            o->cur[3] = 1;
        }
        return 0;
    }
    case OP_SUMMARY: {
        int64_t c = o->cur[0];
        {
            const double *x = o->x[c], *P = o->P[c];
            int64_t nx = o->nx;
            double *out = o->out;
            for (int64_t i = 0; i < nx; i++) out[i] = x[i];
            for (int64_t i = 0; i < nx; i++) out[nx + i] = P[i + i * nx];
            for (int64_t q = 0; q < o->nup; q++) out[2 * nx + q] = P[o->upi[q] + o->upj[q] * nx];
            out[2 * nx + o->nup] = o->nis[0];
        }
        return 0;
    }
    case OP_HOOK:
        if (o->cur[3] && (o->buf == NULL || o->buf[0] != 0.0)) return EV_HOOK;
        return 0;
    case OP_NOISE: {      /* buf: rows of n values; cur: [row, rows]; w: [instant of the row] */
        if (t != o->w[0]) {
            if (o->cur[0] + 1 >= o->cur[1]) return EV_REFILL;
            o->cur[0] += 1;
            o->w[0] = t;
        }
        const double *z = o->buf + o->cur[0] * o->n;
        if (o->flag)      /* a sensor: y = u + bias + std z (ub: bias, yb: std, uidx: u) */
            for (int64_t i = 0; i < o->n; i++) v[o->idx[i]] = (v[o->uidx[i]] + o->ub[i]) + o->yb[i] * z[i];
        else
            for (int64_t i = 0; i < o->n; i++) v[o->idx[i]] = z[i];
        return 0;
    }
    case OP_PRBS: {       /* buf: the bits as 0.0 / 1.0, n of them */
        int64_t q = (int64_t)floor(t / o->a + 1e-9) % o->n;
        if (q < 0) q += o->n;
        v[o->slot] = o->b + (o->buf[q] != 0.0 ? o->c : -o->c);
        return 0;
    }
    case OP_RECORD: {     /* out: rows of [k, diag Q, diag R], n of them; iw: rows written; x, P: Q, R */
        if (!o->cur[3] || o->buf[0] == 0.0) return 0;
        if (o->iw[0] >= o->n) return EV_HOOK;       /* full: Python records (and grows the rows) */
        int64_t c = o->cur[0], nx = o->nx, ny = o->ny;
        double *row = o->out + o->iw[0] * (1 + nx + ny);
        row[0] = (double)o->cur[1];
        for (int64_t i = 0; i < nx; i++) row[1 + i] = o->x[c][i * (nx + 1)];
        for (int64_t i = 0; i < ny; i++) row[1 + nx + i] = o->P[c][i * (ny + 1)];
        o->iw[0] += 1;
        return 0;
    }
    case OP_HOLD:
        for (int64_t i = 0; i < o->nu; i++) o->uprev[i] = v[o->uidx[i]];
        o->cur[2] = 1;
        return 0;
    }
    return 0;
}

/* Run the ops [start, start + len) of the instant t from s->pc on: 0 when all ran, else the
 * event (s->at: the op it is about; s->pc stays on it, to resume there). */
static int run_ops(kstate_t *s, int64_t start, int64_t len, double t) {
    for (; s->pc < len; s->pc++) {
        int e = run_op(s, s->ops + start + s->pc, t);
        if (e) { s->at = start + s->pc; return e; }
    }
    return 0;
}

/* Run from the saved state until an event; the state says where to resume. */
int kernel_run(kstate_t *s) {
    for (;;) {
        if (s->phase == 0 && s->pc == 0) {
            if (s->k > s->k0 && (s->k - s->k0) % s->block == 0) {   /* a block ended */
                if (!block_finite(s)) return EV_NONFINITE;
                s->k0 = s->k;
                s->jb = s->j;
                if (s->k >= s->kstop) return EV_CHUNK;
            }
        }
        int64_t p = s->pattern[s->k % s->L];
        double t = s->t0 + (double)s->k * s->h;
        if (s->phase == 0) {
            int e = run_ops(s, s->out_start[p], s->out_len[p], t);
            if (e) return e;
            s->phase = 1;
            s->pc = 0;
        }
        if (s->phase == 1) {
            s->phase = 2;
            if (s->k % s->m == 0) {
                double *row = s->buf + s->j * s->ncols;
                for (int64_t c = 0; c < s->ncols; c++) row[c] = s->values[s->sel[c]];
                if (s->nint) {
                    int64_t *irow = s->ibuf + s->j * s->nint;
                    for (int64_t c = 0; c < s->nint; c++) irow[c] = s->integers[s->isel[c]];
                }
                s->j += 1;
                if (s->j == s->cap) {
                    if (s->k == s->n) s->phase = 3;
                    return EV_FLUSH;
                }
            }
            if (s->k == s->n) { s->phase = 3; }
        }
        if (s->phase == 3) {                 /* the last instant: no update */
            if (!block_finite(s)) return EV_NONFINITE;
            return EV_DONE;
        }
        if (s->phase == 2) {
            if (s->k == s->n) { s->phase = 3; continue; }
            int e = run_ops(s, s->upd_start[p], s->upd_len[p], t);
            if (e) return e;
        }
        s->phase = 0;
        s->pc = 0;
        s->k += 1;
    }
}
