/* One pass of the registration's joint histogram: rigid map, N-linear interpolation and binning per sample (the
 * compiled path of histogram.JointHistogram; its numpy method is the reference and the fallback, tested equal).
 * By hand: no library bins a rigidly resampled image at sample points outside ITK's own optimiser loop; ahead of
 * time: a registration pays no compiler start-up. A 2D image arrives as a 3D image of one slice.
 *
 * joint_histogram(A, b, P, mflat, mbins, (mi, mj, mk), fbk, bmax, mode, h0, h1[, threads]) -> n_inside
 *   u = A p + b (A 3 x 3, b 3: float64) maps a sample at p (P: 3 x n float64, about the rotation centre) to a
 *   moving continuous index; mflat: moving intensities in bin units (bin centres at integers); mbins: moving bins
 *   (int64); fbk: each sample's fixed bin times the moving bin count (int64); mode 0: the interpolated value to its
 *   nearest bin, 1: split between its two nearest bins (order-1 B-spline Parzen window), 2: partial volume (each
 *   corner's weight to its own bin); h0, h1: zeroed accumulators (n_cells + 1), the histogram is h0 + h1; threads:
 *   the samples split over POSIX threads, each accumulating privately. Samples outside the moving grid (0 <= u <=
 *   size - 1 on every axis) are skipped; n_inside counts the others.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <pthread.h>
#include <stdint.h>
#include <stdlib.h>

#define MAX_THREADS 8

typedef struct {
    const double *a, *o, *p, *m;
    const int64_t *mb, *fb;
    double *g0, *g1;
    Py_ssize_t n, begin, end, mi, mj, mk, inside;
    long bmax;
    int mode;
} Pass;

/* Accumulate the samples [begin, end) of one pass into its g0, g1; count those inside. */
static void *accumulate(void *arg) {
    Pass *t = (Pass *)arg;
    const double *a = t->a, *o = t->o, *p = t->p, *m = t->m;
    const int64_t *mb = t->mb, *fb = t->fb;
    double *g0 = t->g0, *g1 = t->g1;
    const Py_ssize_t n = t->n, mi = t->mi, mj = t->mj, mk = t->mk;
    const long bmax = t->bmax;
    const double hi_i = (double)(mi - 1), hi_j = (double)(mj - 1), hi_k = (double)(mk - 1);
    const Py_ssize_t i0max = mi > 1 ? mi - 2 : 0, j0max = mj > 1 ? mj - 2 : 0, k0max = mk > 1 ? mk - 2 : 0;
    const Py_ssize_t di = mi > 1 ? 1 : 0, dj = mj > 1 ? mi : 0, dk = mk > 1 ? mi * mj : 0;
    const long bmax0 = bmax > 0 ? bmax - 1 : 0;
    Py_ssize_t inside = 0;
    for (Py_ssize_t s = t->begin; s < t->end; s++) {
        const double x = p[s], y = p[n + s], z = p[2 * n + s];
        const double u = a[0] * x + a[1] * y + a[2] * z + o[0];
        const double v = a[3] * x + a[4] * y + a[5] * z + o[1];
        const double w = a[6] * x + a[7] * y + a[8] * z + o[2];
        if (!(u >= 0.0 && u <= hi_i && v >= 0.0 && v <= hi_j && w >= 0.0 && w <= hi_k))
            continue;
        inside++;
        const Py_ssize_t ii = Py_MIN((Py_ssize_t)u, i0max), jj = Py_MIN((Py_ssize_t)v, j0max),
                         kk = Py_MIN((Py_ssize_t)w, k0max);
        const double fx = u - ii, fy = v - jj, fz = w - kk;
        const Py_ssize_t base = kk * mi * mj + jj * mi + ii;
        const Py_ssize_t c[8] = {base, base + di, base + dj, base + dj + di,
                                 base + dk, base + dk + di, base + dk + dj, base + dk + dj + di};
        const int64_t cell0 = fb[s];
        if (t->mode == 2) {
            const double wx[2] = {1.0 - fx, fx}, wy[2] = {1.0 - fy, fy}, wz[2] = {1.0 - fz, fz};
            for (int q = 0; q < 8; q++) {
                const double wt = wx[q & 1] * wy[(q >> 1) & 1] * wz[q >> 2];
                if (wt > 0.0) g0[cell0 + mb[c[q]]] += wt;
            }
            continue;
        }
        double a0 = m[c[0]] + fx * (m[c[1]] - m[c[0]]);
        a0 += fy * (m[c[2]] + fx * (m[c[3]] - m[c[2]]) - a0);
        if (dk) {  /* one slice (a 2D image): its corners 4-7 are 0-3 and fz is 0, which leave a0 as it is */
            const double a2 = m[c[4]] + fx * (m[c[5]] - m[c[4]]);
            a0 += fz * (a2 + fy * (m[c[6]] + fx * (m[c[7]] - m[c[6]]) - a2) - a0);
        }
        if (t->mode == 0) {
            long bin = (long)(a0 + 0.5);
            g0[cell0 + (bin < 0 ? 0 : (bin > bmax ? bmax : bin))] += 1.0;
        } else {
            const double val = a0 < 0.0 ? 0.0 : (a0 > (double)bmax ? (double)bmax : a0);
            const long m0 = Py_MIN((long)val, bmax0);
            const double wt = val - (double)m0;
            g0[cell0 + m0] += 1.0 - wt;
            g1[cell0 + m0 + 1] += wt;
        }
    }
    t->inside = inside;
    return NULL;
}

static PyObject *joint_histogram(PyObject *self, PyObject *args) {
    Py_buffer A, b, P, mflat, mbins, fbk, h0, h1;
    Py_ssize_t mi, mj, mk;
    long bmax;
    int mode, threads = 1;
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*(nnn)y*liw*w*|i", &A, &b, &P, &mflat, &mbins, &mi, &mj, &mk, &fbk, &bmax,
                          &mode, &h0, &h1, &threads))
        return NULL;
    const Py_ssize_t n = fbk.len / (Py_ssize_t)sizeof(int64_t), cells = h0.len / (Py_ssize_t)sizeof(double);
    threads = Py_MAX(1, Py_MIN(threads, MAX_THREADS));
    Pass pass[MAX_THREADS];
    double *extra[MAX_THREADS] = {NULL};
    pthread_t id[MAX_THREADS];
    int started[MAX_THREADS] = {0};
    Py_ssize_t inside = 0;
    Py_BEGIN_ALLOW_THREADS
    for (int k = 0; k < threads; k++) {
        Pass t = {(const double *)A.buf, (const double *)b.buf, (const double *)P.buf, (const double *)mflat.buf,
                  (const int64_t *)mbins.buf, (const int64_t *)fbk.buf, (double *)h0.buf, (double *)h1.buf,
                  n, n * k / threads, n * (k + 1) / threads, mi, mj, mk, 0, bmax, mode};
        if (k > 0) {  /* every other pass accumulates privately; summed into h0, h1 below */
            extra[k] = (double *)calloc(2 * (size_t)cells, sizeof(double));
            if (extra[k] != NULL) { t.g0 = extra[k]; t.g1 = extra[k] + cells; }  /* else: run here, after pass 0 */
        }
        pass[k] = t;
    }
    for (int k = 1; k < threads; k++)
        started[k] = extra[k] != NULL && pthread_create(&id[k], NULL, accumulate, &pass[k]) == 0;
    accumulate(&pass[0]);
    for (int k = 1; k < threads; k++) {
        if (started[k]) pthread_join(id[k], NULL);
        else accumulate(&pass[k]);  /* no thread: this pass runs here */
    }
    for (int k = 0; k < threads; k++) {  /* pass 0 accumulates into h0, h1 themselves */
        inside += pass[k].inside;
        if (extra[k] == NULL) continue;
        for (Py_ssize_t c = 0; c < cells; c++) { pass[0].g0[c] += extra[k][c]; pass[0].g1[c] += extra[k][cells + c]; }
        free(extra[k]);
    }
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&A); PyBuffer_Release(&b); PyBuffer_Release(&P); PyBuffer_Release(&mflat);
    PyBuffer_Release(&mbins); PyBuffer_Release(&fbk); PyBuffer_Release(&h0); PyBuffer_Release(&h1);
    return PyLong_FromSsize_t(inside);
}

static PyMethodDef methods[] = {
    {"joint_histogram", joint_histogram, METH_VARARGS, "Accumulate the joint histogram of rigidly mapped samples."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_histogram", NULL, -1, methods};

PyMODINIT_FUNC PyInit__histogram(void) { return PyModule_Create(&module); }
