/* The step adapter's two-step QP (romoco_drake/rom/step_adapt.py, solve_step_qp) and its swing
 * window (SwingWindow.contains) in C.
 *
 * The same grid search over sigma_1 (the first step's e^{lambda T}), the same exact inner minimum
 * per (sigma_1, sigma_2) and axis (_two_step_axis), the same swing window and CoP shifts, each
 * operation in numpy's order: the numpy code is the reference and the tests hold the two together.
 * In numpy each grid evaluation is about ninety array operations whose fixed cost dominates (a
 * recovery tick of G1 spent 0.3-0.7 ms in the search); here one loop over the grid does the same
 * arithmetic (G1's search with its swing window: 0.09 ms against 0.54).
 *
 * solve(params) takes one float64 buffer laid out by step_qp_kernel.solve and returns
 * (sigma_1, u_x, u_y, shift); window_interval returns one window's bounds at one time.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdlib.h>

#define MAX_NEXT 64
#define MAX_SAMPLES 256
#define MAX_SHIFTS 64
#define MAX_GRID 1024

/* A swing window's bounds as lines in the remaining swing time d (SwingWindow.lines): per axis
 * and sample r, low0 + d slope and high0 + d slope bound the touchdown offset over d, and
 * least0 + d least1 is the offset of least velocity. */
typedef struct {
    int n;
    double low0[2][MAX_SAMPLES], high0[2][MAX_SAMPLES], slope[2][MAX_SAMPLES], least0[2], least1[2];
} Lines;

typedef struct {
    double u_n[2], sigma_n, xi0[2], box_lo[2], box_hi[2], sigma_lo, sigma_hi, w_u, w_t, w_b;
    double lo2[2], hi2[2], g[2], e[2], sigma_n2;
    int n_next;
    double s2[MAX_NEXT];
    int window;
    double s[2], tau, lam, centre[2];
    Lines lines;
    int cop, n_shifts;
    double shifts[MAX_SHIFTS], cop_weight, decay;
} Problem;

/* Whether c replaces best in numpy's argmin (the first of the least; the first NaN wins). */
static int better(double c, double best, int first) { return first || (best == best && (c < best || c != c)); }

/* numpy's maximum/minimum: NaN wins. */
static double np_max(double a, double b) { return (a != a || a > b) ? a : (b != b ? b : (a >= b ? a : b)); }
static double np_min(double a, double b) { return (a != a || a < b) ? a : (b != b ? b : (a <= b ? a : b)); }

/* _two_step_axis for one (sigma_1, sigma_2): the cost and u_1, in numpy's order of operations. */
static double axis(double a, double g, double e, double c, double s2, double lo1, double hi1, double lo2,
                   double hi2, double w_u, double w_b, double *u1_out) {
    double h0 = s2 * c - e;
    double rho = w_b / w_u;
    double k = (w_b / (w_u + w_b)) * s2;
    double q = (w_u * g + w_b * h0) / (w_u + w_b);
    double pinned = w_b * s2 / (w_u + w_b * s2 * s2);
    double base = (w_u / (w_u + w_b * s2 * s2)) * a;
    double at_hi = base + pinned * (h0 - hi2), at_lo = base + pinned * (h0 - lo2);
    double free = a + rho * s2 * (h0 - s2 * a - g) / (1.0 + rho * (1.0 + s2 * s2));
    double u1 = (at_hi * k < q - hi2) ? at_hi : ((at_lo * k > q - lo2) ? at_lo : free);
    u1 = np_min(np_max(u1, lo1), hi1);
    double u2 = np_min(np_max(q - k * u1, lo2), hi2);
    double r1 = u1 - a, r2 = u2 - g, r3 = h0 - s2 * u1 - u2;
    *u1_out = u1;
    return w_u * (r1 * r1 + r2 * r2) + w_b * (r3 * r3);
}

/* SwingWindow.interval at remaining time d from the window's start s: (lo, hi) per axis, or the
 * least-velocity point on an axis whose bounds cross. */
static void window_at(const Lines *w, const double s[2], double d, double lo[2], double hi[2]) {
    for (int ax = 0; ax < 2; ax++) {
        double low = -INFINITY, high = INFINITY;
        int low_nan = 0, high_nan = 0;
        for (int r = 0; r < w->n; r++) {
            double dr = d * w->slope[ax][r];
            double l = dr + w->low0[ax][r], h = dr + w->high0[ax][r];
            if (l != l) low_nan = 1; else if (l > low) low = l;
            if (h != h) high_nan = 1; else if (h < high) high = h;
        }
        if (low_nan) low = NAN;
        if (high_nan) high = NAN;
        double least = w->least0[ax] + d * w->least1[ax];
        int crossed = low > high;
        lo[ax] = s[ax] + d * (crossed ? least : low);
        hi[ax] = s[ax] + d * (crossed ? least : high);
    }
}

/* The first step's box at sigma_1: the reach cut to the swing window, or the window's point
 * nearest the reach where the two do not meet. */
static void first_box(const Problem *p, double s1, double lo[2], double hi[2]) {
    double w_lo[2], w_hi[2];
    window_at(&p->lines, p->s, np_max(log(s1) / p->lam - p->tau, 0.0), w_lo, w_hi);
    for (int ax = 0; ax < 2; ax++) {
        int apart = (w_lo[ax] > p->box_hi[ax]) || (w_hi[ax] < p->box_lo[ax]);
        double nearest = np_min(np_max(p->centre[ax], w_lo[ax]), w_hi[ax]);
        lo[ax] = apart ? nearest : np_max(p->box_lo[ax], w_lo[ax]);
        hi[ax] = apart ? nearest : np_min(p->box_hi[ax], w_hi[ax]);
    }
}

/* The least cost over sigma_2 (and the CoP shifts) at sigma_1 = s1, and its u_1 and shift index;
 * ties go to the first, as numpy's argmin. */
static double evaluate(const Problem *p, double s1, int *best_j, double u[2], int *best_shift) {
    double lo[2] = {p->box_lo[0], p->box_lo[1]}, hi[2] = {p->box_hi[0], p->box_hi[1]};
    if (p->window) first_box(p, s1, lo, hi);
    double d1 = s1 - p->sigma_n, t1 = p->w_t * (d1 * d1);
    double best = NAN;
    for (int j = 0; j < p->n_next; j++) {
        double s2 = p->s2[j], d2 = s2 - p->sigma_n2, t2 = p->w_t * (d2 * d2);
        double cost_x, ux, uy;
        int shift = 0;
        if (!p->cop) {
            cost_x = axis(p->u_n[0], p->g[0], p->e[0], p->xi0[0] * s1, s2, lo[0], hi[0], p->lo2[0], p->hi2[0],
                          p->w_u, p->w_b, &ux);
        } else {
            cost_x = NAN;
            ux = NAN;
            for (int m = 0; m < p->n_shifts; m++) {
                double dm = p->shifts[m], ui;
                double end = p->xi0[0] * s1 + dm * (1.0 - s1 * p->decay);
                double c = axis(p->u_n[0], p->g[0], p->e[0], end, s2, lo[0], hi[0], p->lo2[0], p->hi2[0],
                                p->w_u, p->w_b, &ui) + p->cop_weight * (dm * dm);
                if (better(c, cost_x, m == 0)) { cost_x = c; ux = ui; shift = m; }
            }
        }
        double cost_y = axis(p->u_n[1], p->g[1], p->e[1], p->xi0[1] * s1, s2, lo[1], hi[1], p->lo2[1], p->hi2[1],
                             p->w_u, p->w_b, &uy);
        double total = t1 + t2 + cost_x + cost_y;
        if (better(total, best, j == 0)) { best = total; *best_j = j; u[0] = ux; u[1] = uy; *best_shift = shift; }
    }
    return best;
}

/* np.linspace(start, stop, num). */
static void linspace(double start, double stop, int num, double *out) {
    double step = (stop - start) / (double)(num - 1);
    for (int i = 0; i < num; i++) out[i] = (double)i * step + start;
    out[num - 1] = stop;
}

/* The argmin over a sigma_1 grid (first of the least, NaN first as numpy's argmin). */
static int least_row(const Problem *p, const double *sigma, int n, double u[2], int *shift) {
    int k = 0, j = 0, sh = 0;
    double best = 0.0, uu[2] = {NAN, NAN};
    for (int i = 0; i < n; i++) {
        double c = evaluate(p, sigma[i], &j, uu, &sh);
        if (better(c, best, i == 0)) {
            best = c; k = i; u[0] = uu[0]; u[1] = uu[1]; *shift = sh;
        }
    }
    return k;
}

static int take(const double *buf, Py_ssize_t n, Py_ssize_t *at, double *out, Py_ssize_t count) {
    if (*at + count > n) return 0;
    for (Py_ssize_t i = 0; i < count; i++) out[i] = buf[*at + i];
    *at += count;
    return 1;
}

static int parse(const double *buf, Py_ssize_t n, Problem *p, int grid[3]) {
    Py_ssize_t at = 0;
    double v[8];
    if (!take(buf, n, &at, v, 3)) return 0;
    for (int i = 0; i < 3; i++) grid[i] = (int)v[i];
    if (!take(buf, n, &at, p->u_n, 2) || !take(buf, n, &at, &p->sigma_n, 1) || !take(buf, n, &at, p->xi0, 2)
        || !take(buf, n, &at, p->box_lo, 2) || !take(buf, n, &at, p->box_hi, 2) || !take(buf, n, &at, v, 5))
        return 0;
    p->sigma_lo = v[0]; p->sigma_hi = v[1]; p->w_u = v[2]; p->w_t = v[3]; p->w_b = v[4];
    if (!take(buf, n, &at, p->lo2, 2) || !take(buf, n, &at, p->hi2, 2) || !take(buf, n, &at, p->g, 2)
        || !take(buf, n, &at, p->e, 2) || !take(buf, n, &at, &p->sigma_n2, 1) || !take(buf, n, &at, v, 1))
        return 0;
    p->n_next = (int)v[0];
    if (p->n_next < 1 || p->n_next > MAX_NEXT || !take(buf, n, &at, p->s2, p->n_next) || !take(buf, n, &at, v, 2))
        return 0;
    p->window = (int)v[0];
    p->lines.n = (int)v[1];
    if (p->window) {
        if (p->lines.n < 1 || p->lines.n > MAX_SAMPLES) return 0;
        if (!take(buf, n, &at, p->s, 2) || !take(buf, n, &at, &p->tau, 1) || !take(buf, n, &at, &p->lam, 1)
            || !take(buf, n, &at, p->centre, 2))
            return 0;
        Lines *w = &p->lines;
        for (int ax = 0; ax < 2; ax++)
            if (!take(buf, n, &at, w->low0[ax], w->n) || !take(buf, n, &at, w->high0[ax], w->n)
                || !take(buf, n, &at, w->slope[ax], w->n))
                return 0;
        if (!take(buf, n, &at, w->least0, 2) || !take(buf, n, &at, w->least1, 2)) return 0;
    }
    if (!take(buf, n, &at, v, 2)) return 0;
    p->cop = (int)v[0];
    p->n_shifts = (int)v[1];
    if (p->cop) {
        if (p->n_shifts < 1 || p->n_shifts > MAX_SHIFTS || !take(buf, n, &at, p->shifts, p->n_shifts)
            || !take(buf, n, &at, &p->cop_weight, 1) || !take(buf, n, &at, &p->decay, 1))
            return 0;
    }
    return at == n && grid[0] >= 2 && grid[0] <= MAX_GRID && grid[1] >= 2 && grid[1] <= MAX_GRID && grid[2] >= 0;
}

static PyObject *solve(PyObject *Py_UNUSED(self), PyObject *args) {
    Py_buffer view;
    if (!PyArg_ParseTuple(args, "y*", &view)) return NULL;
    Problem *p = malloc(sizeof(Problem));
    int grid[3];
    if (p == NULL) { PyBuffer_Release(&view); return PyErr_NoMemory(); }
    int ok = view.len % sizeof(double) == 0
             && parse((const double *)view.buf, view.len / (Py_ssize_t)sizeof(double), p, grid);
    PyBuffer_Release(&view);
    if (!ok) {
        free(p);
        PyErr_SetString(PyExc_ValueError, "step QP parameters: malformed buffer");
        return NULL;
    }
    double sigma[MAX_GRID], u[2] = {NAN, NAN};
    int n = grid[0], k, shift = 0;
    linspace(p->sigma_lo, p->sigma_hi, n, sigma);
    for (int round = 0; round < grid[2]; round++) {
        k = least_row(p, sigma, n, u, &shift);
        double start = sigma[k > 0 ? k - 1 : 0], stop = sigma[k + 1 < n ? k + 1 : n - 1];
        n = grid[1];
        linspace(start, stop, n, sigma);
    }
    k = least_row(p, sigma, n, u, &shift);
    double shift_value = p->cop ? p->shifts[shift] : 0.0;
    PyObject *out = Py_BuildValue("dddd", sigma[k], u[0], u[1], shift_value);
    free(p);
    return out;
}

/* SwingWindow.interval at one time t, its lines built here: samples is [n, peak, HG, KG, G2,
 * H (n), G (n), K/G (n)] (step_adapt's constants), the rest the window's fields. */
static PyObject *window_interval(PyObject *Py_UNUSED(self), PyObject *args) {
    Py_buffer view;
    double s[2], v[2], a[2], speed, tau, t, lo[2], hi[2];
    if (!PyArg_ParseTuple(args, "y*ddddddddd", &view, &s[0], &s[1], &v[0], &v[1], &a[0], &a[1], &speed, &tau, &t))
        return NULL;
    const double *c = (const double *)view.buf;
    Py_ssize_t size = view.len / (Py_ssize_t)sizeof(double);
    int n = size >= 5 ? (int)c[0] : -1;
    if (n < 1 || n > MAX_SAMPLES || size != 5 + 3 * (Py_ssize_t)n || view.len % sizeof(double) != 0) {
        PyBuffer_Release(&view);
        PyErr_SetString(PyExc_ValueError, "swing window samples: malformed buffer");
        return NULL;
    }
    const double peak = c[1], hg = c[2], kg = c[3], g2 = c[4], *H = c + 5, *G = H + n, *KG = G + n;
    double vmax = peak * speed;
    Lines *w = malloc(sizeof(Lines));
    if (w == NULL) { PyBuffer_Release(&view); return PyErr_NoMemory(); }
    w->n = n;
    for (int ax = 0; ax < 2; ax++) {  /* SwingWindow.lines, in its order of operations */
        for (int r = 0; r < n; r++) {
            w->low0[ax][r] = (-vmax - v[ax] * H[r]) / G[r];
            w->high0[ax][r] = (vmax - v[ax] * H[r]) / G[r];
            w->slope[ax][r] = -a[ax] * KG[r];
        }
        w->least0[ax] = -v[ax] * hg / g2;
        w->least1[ax] = -a[ax] * kg / g2;
    }
    window_at(w, s, np_max(t - tau, 0.0), lo, hi);
    free(w);
    PyBuffer_Release(&view);
    return Py_BuildValue("dddd", lo[0], lo[1], hi[0], hi[1]);
}

static PyMethodDef methods[] = {
    {"solve", solve, METH_VARARGS, "solve(params) -> (sigma_1, u_x, u_y, shift): the two-step QP's solution"},
    {"window_interval", window_interval, METH_VARARGS,
     "window_interval(samples, s_x, s_y, v_x, v_y, a_x, a_y, speed, tau, t) -> (lo_x, lo_y, hi_x, hi_y)"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_step_qp", "The step adapter QP in C.", -1, methods,
                                    NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__step_qp(void) { return PyModule_Create(&module); }
