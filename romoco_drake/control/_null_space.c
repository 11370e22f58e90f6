/* Null spaces and minimum-norm solutions for the momentum controller's hierarchy
 * (romoco_drake/control/hqp.py, null_space), by Householder QR with column pivoting.
 *
 * For A (m x n), the columns of M = A^T are factored as M P = Q R, the pivot taking the column of
 * largest remaining norm each step, so |R_kk| does not increase along the diagonal and stops, at
 * the rank r, where it falls to rtol |R_00| or below. Then null(A) = span(Q[:, r:]) and the
 * minimum-norm x with A x = b is Q[:, :r] y, R_r^T y = (P^T b)_r. Both need only the first r
 * reflectors. numpy's SVD does the same job (and stays the fallback), but on the controller's
 * 6-12 x 20-40 matrices its fixed cost and cold caches dominate: 35-55 us a call inside a tick.
 *
 * qr_null(a, m, n, b, has_b, rtol, out_n, out_x) reads A (m x n, C order) and b (m), writes the
 * basis into out_n (n x (n - r), C order, from its start) and x into out_x, and returns r.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define MAX_DIM 512

/* Factors the m columns of M (column j at M + j n, length n) up to the rank; reflector k is
 * H_k = I - beta_k v_k v_k^T with v_k in V + k n (entries k..n-1). Returns the rank. */
static int factor(double *M, int n, int m, int *perm, double *V, double *beta, double rtol) {
    int kmax = n < m ? n : m;
    double r00 = 0.0;
    for (int j = 0; j < m; j++) perm[j] = j;
    for (int k = 0; k < kmax; k++) {
        int p = k;
        double best = -1.0;
        for (int j = k; j < m; j++) {
            const double *c = M + (size_t)j * n;
            double s = 0.0;
            for (int i = k; i < n; i++) s += c[i] * c[i];
            if (s > best) { best = s; p = j; }
        }
        double norm = sqrt(best);
        if (k == 0) r00 = norm;
        if (!(norm > rtol * r00) || norm == 0.0) return k; /* the rest is zero to rtol (or NaN) */
        if (p != k) {
            double *a = M + (size_t)k * n, *b = M + (size_t)p * n;
            for (int i = 0; i < n; i++) { double t = a[i]; a[i] = b[i]; b[i] = t; }
            int t = perm[k]; perm[k] = perm[p]; perm[p] = t;
        }
        double *c = M + (size_t)k * n, *v = V + (size_t)k * n;
        double alpha = c[k] >= 0.0 ? -norm : norm;
        double vv = 0.0;
        for (int i = k; i < n; i++) v[i] = c[i];
        v[k] -= alpha;
        for (int i = k; i < n; i++) vv += v[i] * v[i];
        beta[k] = vv > 0.0 ? 2.0 / vv : 0.0;
        c[k] = alpha;
        for (int i = k + 1; i < n; i++) c[i] = 0.0;
        for (int j = k + 1; j < m; j++) {
            double *cj = M + (size_t)j * n, s = 0.0;
            for (int i = k; i < n; i++) s += v[i] * cj[i];
            s *= beta[k];
            for (int i = k; i < n; i++) cj[i] -= s * v[i];
        }
    }
    return kmax;
}

/* x (length n) <- H_0 ... H_{r-1} x. */
static void apply_q(const double *V, const double *beta, int n, int r, double *x) {
    for (int k = r - 1; k >= 0; k--) {
        const double *v = V + (size_t)k * n;
        double s = 0.0;
        for (int i = k; i < n; i++) s += v[i] * x[i];
        s *= beta[k];
        for (int i = k; i < n; i++) x[i] -= s * v[i];
    }
}

static PyObject *qr_null(PyObject *self, PyObject *args) {
    Py_buffer a, b, out_n, out_x;
    int m, n, has_b;
    double rtol;
    if (!PyArg_ParseTuple(args, "y*iiy*pdw*w*", &a, &m, &n, &b, &has_b, &rtol, &out_n, &out_x)) return NULL;
    PyObject *result = NULL;
    double *work = NULL;
    if (m < 0 || n < 1 || m > MAX_DIM || n > MAX_DIM || a.len != (Py_ssize_t)sizeof(double) * m * n
        || (has_b && b.len != (Py_ssize_t)sizeof(double) * m)
        || out_n.len < (Py_ssize_t)sizeof(double) * n * n || out_x.len < (Py_ssize_t)sizeof(double) * n) {
        PyErr_SetString(PyExc_ValueError, "qr_null: buffer sizes do not match (m, n)");
        goto done;
    }
    /* M = A^T column by column is A's rows; V holds the reflectors; one allocation for both. */
    size_t mn = (size_t)m * n, nn = (size_t)n * n;
    work = malloc(sizeof(double) * (mn + nn + 2 * (size_t)n + 1) + sizeof(int) * ((size_t)m + 1));
    if (work == NULL) { PyErr_NoMemory(); goto done; }
    double *M = work, *V = M + mn, *beta = V + nn, *y = beta + n;
    int *perm = (int *)(y + n + 1);
    memcpy(M, a.buf, sizeof(double) * mn);
    int r = factor(M, n, m, perm, V, beta, rtol);
    int nz = n - r;
    double *N = out_n.buf, *col = y;
    for (int c = 0; c < nz; c++) { /* column c of the basis: Q e_{r+c} */
        memset(col, 0, sizeof(double) * n);
        col[r + c] = 1.0;
        apply_q(V, beta, n, r, col);
        for (int i = 0; i < n; i++) N[(size_t)i * nz + c] = col[i];
    }
    double *x = out_x.buf;
    memset(x, 0, sizeof(double) * n);
    if (has_b) { /* R_r^T y = (P^T b)_r forward, R[j][k] = M[k n + j]; x = Q [y; 0] */
        const double *bb = b.buf;
        for (int k = 0; k < r; k++) {
            double s = bb[perm[k]];
            for (int j = 0; j < k; j++) s -= M[(size_t)k * n + j] * x[j];
            x[k] = s / M[(size_t)k * n + k];
        }
        apply_q(V, beta, n, r, x);
    }
    result = PyLong_FromLong(r);
done:
    free(work);
    PyBuffer_Release(&a);
    PyBuffer_Release(&b);
    PyBuffer_Release(&out_n);
    PyBuffer_Release(&out_x);
    return result;
}

static PyMethodDef methods[] = {
    {"qr_null", qr_null, METH_VARARGS,
     "qr_null(a, m, n, b, has_b, rtol, out_n, out_x) -> rank: null(A) into out_n, min-norm x into out_x."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_null_space",
                                    "Null spaces by pivoted Householder QR.", -1, methods,
                                    NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__null_space(void) { return PyModule_Create(&module); }
