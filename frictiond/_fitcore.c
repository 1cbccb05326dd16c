/*
 * frictiond._fitcore: the estimator's per-update numerics, compiled.
 *
 * The same computation as `LugreTrustRegionEstimator._normal` (static LuGre rows of the
 * window, weighted, plus the priors and the wheel ties, as normal equations) driven by the
 * same iterations as `trust_region.solve_normal` (Coleman-Li scaled trust region, exact
 * subproblem by eigen-decomposition and Newton on the secular equation, projected steps).
 * In Python those are a few hundred small numpy calls per update; here they are a few
 * microseconds. The Python path stays the reference and the fallback where no compiler was
 * available at install (tests compare the two).
 *
 * The tyre-model functions take the LuGre parameters as one tuple, `params` =
 * (mu_c, mu_s - mu_c, alpha, sigma0, sigma0·L, v_s, sigma2): tyre_model.compiled_params.
 *
 * Arrays arrive through the buffer protocol (C-contiguous float64, the wheel index as intp),
 * so building needs no numpy headers. Pure numerics: nothing of CAN.
 */
#include "_ccommon.h"
#include <math.h>

#define NW 4            /* wheels: one ln θ each */
#define NP 7            /* parameters: 4 ln θ, σ0, v_s, σ2 (scaled) */
#define NT 4            /* soft ties between the wheels' ln θ */
#define SMALL_Z 1e-4    /* below this, F(Z) by its series (tyre_model._SMALL_Z) */

typedef struct {
    Py_ssize_t m;
    const double *pow_lam_v, *stiff, *lam_v, *mu, *sw;
    const Py_ssize_t *wheel;
    const double *prior, *inv_prior_std, *tie;      /* tie: NT x NW, rows (e_a - e_b)/rel */
    double mu_c, dmu, alpha, sc4, sc5, sc6;
} Problem;

#define ROW 5   /* a sample's unweighted row: ∂μ/∂ln θ_wheel, ∂μ/∂(σ0, v_s, σ2) scaled, μ_model − μ */

/* 1/2 |r|^2, J^T r, J^T J at x; the weighted data residuals into r_data. `rows` (m x ROW) holds
 * the unweighted rows of the first `cached_n` samples at this x (an earlier call's); the others
 * are computed into it. Two passes, the rows and then their sums: a row's exp, expm1 and
 * divisions form a long dependency chain, and with the sums out of the way the processor
 * overlaps several rows' chains (1.7x faster on this VM, the same operations in the same order). */
static void evaluate(const Problem *p, const double *x, double *cost, double *g, double *N, double *r_data,
                     double *rows, Py_ssize_t cached_n)
{
    double thetas[NW], inv_t[NW], Zk[NW];
    const double sigma0 = x[4] * p->sc4, v_s = x[5] * p->sc5, sigma2 = x[6] * p->sc6;
    const double v_pow = pow(v_s, -p->alpha);
    const double k4 = p->sc4 / sigma0, k5 = p->dmu * p->alpha / v_s * p->sc5;
    /* Accumulators: per wheel the θ-entries with themselves and the shared ones; the
     * shared 3x3 block; the gradient and cost. */
    double tt[NW] = {0}, ts[NW][3], ss[3][3], gt_[NW] = {0}, gs[3] = {0}, rr = 0.0;
    memset(ts, 0, sizeof ts);
    memset(ss, 0, sizeof ss);
    for (int i = 0; i < NW; i++) {
        thetas[i] = exp(x[i]);
        inv_t[i] = 1.0 / thetas[i];
        Zk[i] = thetas[i] * sigma0;
    }
    for (Py_ssize_t j = cached_n; j < p->m; j++) {
        const int wi = (int)p->wheel[j];
        double *u = rows + ROW * j;
        const double ratio = p->pow_lam_v[j] * v_pow;
        const double e = exp(-ratio);
        const double gg = e * p->dmu + p->mu_c;
        const double Z = Zk[wi] * p->stiff[j] / gg;
        double F, ZdF;
        if (Z < SMALL_Z) {
            F = Z / 2.0 - Z * Z / 6.0;
            ZdF = Z * (0.5 - Z / 3.0);
        } else {
            /* (1 − e^−Z by exp beyond Z = 0.5, where it is as exact: glibc's expm1 costs
             * several times exp there, and this is most of a row's work) */
            const double om = Z > 0.5 ? 1.0 - exp(-Z) : -expm1(-Z), iz = 1.0 / Z;
            F = 1.0 - om * iz;
            ZdF = (om * (1.0 + Z) - Z) * iz;
        }
        const double FmZ = F - ZdF, gt = gg * inv_t[wi], lv = p->lam_v[j];
        u[0] = -(gt * FmZ);
        u[1] = gt * ZdF * k4;
        u[2] = FmZ * inv_t[wi] * e * ratio * k5;
        u[3] = lv * p->sc6;
        u[4] = gt * F + sigma2 * lv - p->mu[j];
    }
    for (Py_ssize_t j = 0; j < p->m; j++) {
        const int wi = (int)p->wheel[j];
        const double *u = rows + ROW * j;
        const double w = p->sw[j];
        const double a = u[0] * w, s0 = u[1] * w, s1 = u[2] * w, s2 = u[3] * w, r = u[4] * w;
        r_data[j] = r;
        tt[wi] += a * a;
        ts[wi][0] += a * s0;
        ts[wi][1] += a * s1;
        ts[wi][2] += a * s2;
        ss[0][0] += s0 * s0;
        ss[0][1] += s0 * s1;
        ss[0][2] += s0 * s2;
        ss[1][1] += s1 * s1;
        ss[1][2] += s1 * s2;
        ss[2][2] += s2 * s2;
        gt_[wi] += a * r;
        gs[0] += s0 * r;
        gs[1] += s1 * r;
        gs[2] += s2 * r;
        rr += r * r;
    }
    memset(N, 0, NP * NP * sizeof(double));
    for (int i = 0; i < NW; i++) {
        N[i * NP + i] = tt[i];
        for (int k = 0; k < 3; k++)
            N[i * NP + NW + k] = N[(NW + k) * NP + i] = ts[i][k];
        g[i] = gt_[i];
    }
    for (int a = 0; a < 3; a++) {
        for (int b = a; b < 3; b++)
            N[(NW + a) * NP + NW + b] = N[(NW + b) * NP + NW + a] = ss[a][b];
        g[NW + a] = gs[a];
    }
    /* Priors: rows (x - prior)/std. */
    for (int i = 0; i < NP; i++) {
        const double q = p->inv_prior_std[i], d = (x[i] - p->prior[i]) * q;
        N[i * NP + i] += q * q;
        g[i] += q * d;
        rr += d * d;
    }
    /* Ties: rows T x[:NW]. */
    for (int t = 0; t < NT; t++) {
        const double *row = p->tie + t * NW;
        double d = 0.0;
        for (int i = 0; i < NW; i++)
            d += row[i] * x[i];
        for (int i = 0; i < NW; i++) {
            g[i] += row[i] * d;
            for (int k = 0; k < NW; k++)
                N[i * NP + k] += row[i] * row[k];
        }
        rr += d * d;
    }
    *cost = 0.5 * rr;
}

/* Symmetric eigen-decomposition of an NP x NP matrix by cyclic Jacobi rotations:
 * eigenvalues ascending in w, eigenvectors in the columns of Q. */
static void eigh(const double *H, double *w, double *Q)
{
    double A[NP][NP], V[NP][NP];
    for (int i = 0; i < NP; i++)
        for (int k = 0; k < NP; k++) {
            A[i][k] = H[i * NP + k];
            V[i][k] = (i == k);
        }
    for (int sweep = 0; sweep < 60; sweep++) {
        double off = 0.0, diag = 0.0;
        for (int i = 0; i < NP; i++) {
            diag += A[i][i] * A[i][i];
            for (int k = i + 1; k < NP; k++)
                off += A[i][k] * A[i][k];
        }
        if (off <= 1e-32 * diag || off == 0.0)
            break;
        for (int pp = 0; pp < NP - 1; pp++)
            for (int q = pp + 1; q < NP; q++) {
                const double apq = A[pp][q];
                if (apq == 0.0)
                    continue;
                const double tau = (A[q][q] - A[pp][pp]) / (2.0 * apq);
                const double t = (tau >= 0 ? 1.0 : -1.0) / (fabs(tau) + sqrt(1.0 + tau * tau));
                const double c = 1.0 / sqrt(1.0 + t * t), s = t * c;
                for (int k = 0; k < NP; k++) {
                    const double akp = A[k][pp], akq = A[k][q];
                    A[k][pp] = c * akp - s * akq;
                    A[k][q] = s * akp + c * akq;
                }
                for (int k = 0; k < NP; k++) {
                    const double apk = A[pp][k], aqk = A[q][k];
                    A[pp][k] = c * apk - s * aqk;
                    A[q][k] = s * apk + c * aqk;
                }
                for (int k = 0; k < NP; k++) {
                    const double vkp = V[k][pp], vkq = V[k][q];
                    V[k][pp] = c * vkp - s * vkq;
                    V[k][q] = s * vkp + c * vkq;
                }
            }
    }
    int order[NP];
    for (int i = 0; i < NP; i++)
        order[i] = i;
    for (int i = 1; i < NP; i++) {      /* insertion sort by eigenvalue */
        const int o = order[i];
        int k = i - 1;
        while (k >= 0 && A[order[k]][order[k]] > A[o][o]) {
            order[k + 1] = order[k];
            k--;
        }
        order[k + 1] = o;
    }
    for (int c = 0; c < NP; c++) {
        w[c] = A[order[c]][order[c]];
        for (int r = 0; r < NP; r++)
            Q[r * NP + c] = V[r][order[c]];
    }
}

/* argmin 1/2 s^T H s + g^T s over |s| <= radius, from H = Q diag(w) Q^T and a = Q^T g
 * (trust_region._subproblem). */
static void subproblem(const double *w, const double *Q, const double *a, double radius, double *s)
{
    double c[NP];
    const double w0 = w[0], w_last = w[NP - 1];
    int interior = 0;
    if (w0 > 1e-12 * fmax(1.0, fabs(w_last))) {
        double ss = 0.0;
        for (int i = 0; i < NP; i++) {
            c[i] = a[i] / w[i];
            ss += c[i] * c[i];
        }
        interior = ss <= radius * radius;
    }
    if (!interior) {
        const double lam_low = fmax(0.0, -w0) + 1e-14 * fmax(1.0, fabs(w_last));
        double norm_a = 0.0;
        for (int i = 0; i < NP; i++)
            norm_a += a[i] * a[i];
        norm_a = sqrt(norm_a);
        double lam = fmax(lam_low, norm_a / radius - w0);
        for (int it = 0; it < 50; it++) {
            double ss = 0.0, s3 = 0.0;
            int bad = 0;
            for (int i = 0; i < NP; i++) {
                const double den = w[i] + lam;
                if (den == 0.0) {
                    bad = 1;
                    break;
                }
                const double inv = 1.0 / den, si = a[i] * inv;
                ss += si * si;
                s3 += si * si * inv;
            }
            if (bad)
                break;
            const double ns = sqrt(ss);
            if (ns == 0.0)
                break;
            const double phi = 1.0 / radius - 1.0 / ns;
            if (fabs(phi) * radius < 1e-6)
                break;
            const double dns = -s3 / ns;
            const double step = phi / (dns / (ns * ns));
            if (!isfinite(step))
                break;
            lam = fmax(lam - step, lam_low);
        }
        for (int i = 0; i < NP; i++)
            c[i] = a[i] / (w[i] + lam);
    }
    for (int r = 0; r < NP; r++) {
        double v = 0.0;
        for (int k = 0; k < NP; k++)
            v += Q[r * NP + k] * c[k];
        s[r] = -v;
    }
}

/* The Newton step s = -H^{-1} g when it is certainly subproblem()'s answer: H positive definite
 * with its smallest eigenvalue provably above subproblem()'s threshold (1/|H^{-1}|_F bounds it
 * from below, the largest row sum bounds the largest from above) and |s| <= radius. Then the
 * eigen-decomposition, most of an iteration's cost, is not needed. 0: use subproblem(). */
static int newton_step(const double *H, const double *g, double radius, double *s)
{
    double L[NP][NP], inv[NP][NP];
    double row_max = 0.0;
    for (int i = 0; i < NP; i++) {
        double row = 0.0;
        for (int k = 0; k < NP; k++)
            row += fabs(H[i * NP + k]);
        row_max = fmax(row_max, row);
        for (int k = 0; k <= i; k++) {
            double v = H[i * NP + k];
            for (int j = 0; j < k; j++)
                v -= L[i][j] * L[k][j];
            if (k == i) {
                if (!(v > 0.0))
                    return 0;
                L[i][i] = sqrt(v);
            } else
                L[i][k] = v / L[k][k];
        }
    }
    /* H^{-1} column by column: L y = e_c, then L^T z = y */
    double frob = 0.0;
    for (int c = 0; c < NP; c++) {
        double y[NP];
        for (int i = 0; i < NP; i++) {
            double v = (i == c);
            for (int j = 0; j < i; j++)
                v -= L[i][j] * y[j];
            y[i] = v / L[i][i];
        }
        for (int i = NP - 1; i >= 0; i--) {
            double v = y[i];
            for (int j = i + 1; j < NP; j++)
                v -= L[j][i] * inv[j][c];
            inv[i][c] = v / L[i][i];
            frob += inv[i][c] * inv[i][c];
        }
    }
    if (!(1.0 / sqrt(frob) > 1e-12 * fmax(1.0, row_max)))
        return 0;
    double ss = 0.0;
    for (int i = 0; i < NP; i++) {
        double v = 0.0;
        for (int k = 0; k < NP; k++)
            v += inv[i][k] * g[k];
        s[i] = -v;
        ss += v * v;
    }
    return ss <= radius * radius;
}

static double norm(const double *v)
{
    double s = 0.0;
    for (int i = 0; i < NP; i++)
        s += v[i] * v[i];
    return sqrt(s);
}

typedef struct {
    double cost, radius;
    int iterations, converged, evaluations;
} Outcome;

/* trust_region.solve_normal on `evaluate`: x in/out; g, N, r_data at the returned x. rows and
 * rows_trial have room for m x ROW values each: rows holds the first cached_n samples' rows at
 * rows_x on entry (rows_x is read only when cached_n > 0), and all rows at x on return. */
static Outcome solve(const Problem *p, double *x, const double *lb, const double *ub, double radius,
                     int max_iterations, double ftol, double xtol, double gtol, int max_rejections,
                     double predicted_ftol, double *g, double *N, double *r_data, double *r_trial,
                     double *rows, const double *rows_x, Py_ssize_t cached_n, double *rows_trial)
{
    double inner_lb[NP], inner_ub[NP];
    int fin_lb[NP], fin_ub[NP];
    for (int i = 0; i < NP; i++) {
        fin_lb[i] = isfinite(lb[i]);
        fin_ub[i] = isfinite(ub[i]);
        const double span = isfinite(ub[i] - lb[i]) ? ub[i] - lb[i] : 1.0;
        inner_lb[i] = lb[i] + 1e-10 * span;
        inner_ub[i] = ub[i] - 1e-10 * span;
        x[i] = fmin(fmax(fmin(fmax(x[i], lb[i]), ub[i]), inner_lb[i]), inner_ub[i]);
    }
    Outcome out = {0.0, radius, 0, 0, 1};
    double cost;
    /* The row cache holds the rows at rows_x (the last call's result): usable only at that point. */
    for (int i = 0; i < NP && cached_n > 0; i++)
        if (x[i] != rows_x[i])
            cached_n = 0;
    evaluate(p, x, &cost, g, N, r_data, rows, cached_n);
    double *rows_cur = rows, *rows_try = rows_trial;
    if (!isfinite(radius) || radius <= 0) {
        double s = 0.0;
        for (int i = 0; i < NP; i++) {
            double v = 1.0;
            if (g[i] > 0 && fin_lb[i])
                v = x[i] - lb[i];
            else if (g[i] < 0 && fin_ub[i])
                v = ub[i] - x[i];
            s += x[i] * x[i] / v;
        }
        radius = sqrt(s);
        if (radius == 0.0)
            radius = 1.0;
    }
    double g_new[NP], N_new[NP * NP], x_new[NP];
    double *r_cur = r_data, *r_try = r_trial;
    while (out.iterations < max_iterations) {
        double d[NP], g_h[NP], g_dv[NP], gv_max = 0.0, gh_max = 0.0;
        int has_nan = 0;
        for (int i = 0; i < NP; i++) {
            double vi;
            g_dv[i] = 0.0;
            if (g[i] > 0 && fin_lb[i]) {
                vi = x[i] - lb[i];
                g_dv[i] = g[i];
            } else if (g[i] < 0 && fin_ub[i]) {
                vi = ub[i] - x[i];
                g_dv[i] = -g[i];
            } else
                vi = 1.0;
            const double gv = fabs(g[i] * vi);
            has_nan = has_nan || gv != gv;
            gv_max = gv > gv_max ? gv : gv_max;
            d[i] = vi > 0 ? sqrt(vi) : 0.0;
            g_h[i] = d[i] * g[i];
            gh_max = fabs(g_h[i]) > gh_max ? fabs(g_h[i]) : gh_max;
        }
        if (!has_nan && gv_max < gtol) {
            out.converged = 1;
            break;
        }
        double H[NP * NP], w[NP], Q[NP * NP], a[NP];
        int finite = 1;
        for (int i = 0; i < NP; i++)
            for (int k = 0; k < NP; k++) {
                H[i * NP + k] = N[i * NP + k] * d[i] * d[k] + (i == k ? g_dv[i] : 0.0);
                finite = finite && isfinite(H[i * NP + k]);
            }
        if (!finite)
            break;
        int have_eigen = 0;
        out.iterations++;
        const double theta = fmax(0.995, 1.0 - gh_max);
        double upper_room[NP], lower_room[NP];
        for (int i = 0; i < NP; i++) {
            upper_room[i] = theta * (ub[i] - x[i]);
            lower_room[i] = theta * (lb[i] - x[i]);
        }
        double cost_new = cost, actual = 0.0, s[NP], s_h[NP];
        int accepted = 0;
        for (int attempt = 0; attempt < max_rejections; attempt++) {
            if (have_eigen || !newton_step(H, g_h, radius, s_h)) {
                if (!have_eigen) {
                    eigh(H, w, Q);
                    for (int k = 0; k < NP; k++) {
                        a[k] = 0.0;
                        for (int i = 0; i < NP; i++)
                            a[k] += g_h[i] * Q[i * NP + k];
                    }
                    have_eigen = 1;
                }
                subproblem(w, Q, a, radius, s_h);
            }
            int outside = 0;
            for (int i = 0; i < NP; i++) {
                s[i] = d[i] * s_h[i];
                outside = outside || s[i] > upper_room[i] || s[i] < lower_room[i];
            }
            if (outside)
                for (int i = 0; i < NP; i++) {
                    s[i] = fmin(fmax(s[i], lower_room[i]), upper_room[i]);
                    s_h[i] = s[i] / d[i];
                }
            double gs = 0.0, sHs = 0.0;
            for (int i = 0; i < NP; i++) {
                gs += g_h[i] * s_h[i];
                double hs = 0.0;
                for (int k = 0; k < NP; k++)
                    hs += H[i * NP + k] * s_h[k];
                sHs += s_h[i] * hs;
            }
            const double predicted = -(gs + 0.5 * sHs);
            if (predicted_ftol > 0 && predicted < predicted_ftol * cost) {
                out.converged = 1;
                goto done;
            }
            for (int i = 0; i < NP; i++)
                x_new[i] = fmin(fmax(x[i] + s[i], inner_lb[i]), inner_ub[i]);
            evaluate(p, x_new, &cost_new, g_new, N_new, r_try, rows_try, 0);
            out.evaluations++;
            actual = cost - cost_new;
            const double step_norm = norm(s_h);
            const double ratio = predicted > 0 ? actual / predicted : -1.0;
            if (ratio < 0.25)
                radius = step_norm > 0 ? 0.25 * step_norm : 0.25 * radius;
            else if (ratio > 0.75 && step_norm >= 0.95 * radius)
                radius *= 2.0;
            if (actual > 0 && isfinite(cost_new)) {
                accepted = 1;
                break;
            }
            if (radius < 1e-12 * (1.0 + norm(x))) {
                out.converged = 1;
                goto done;
            }
        }
        if (!accepted) {
            out.converged = 1;
            goto done;
        }
        const double x_norm = norm(x);
        memcpy(x, x_new, sizeof x_new);
        memcpy(g, g_new, sizeof g_new);
        memcpy(N, N_new, sizeof N_new);
        double *tmp = r_cur;
        r_cur = r_try;
        r_try = tmp;
        tmp = rows_cur;
        rows_cur = rows_try;
        rows_try = tmp;
        const int small_cost = actual < ftol * cost;
        const int small_step = norm(s) < xtol * (xtol + x_norm);
        cost = cost_new;
        if (small_cost || small_step) {
            out.converged = 1;
            break;
        }
    }
done:
    if (r_cur != r_data)
        memcpy(r_data, r_cur, p->m * sizeof(double));
    if (rows_cur != rows)
        memcpy(rows, rows_cur, ROW * p->m * sizeof(double));
    out.cost = cost;
    out.radius = radius;
    return out;
}

/* ---------------------------------------------------------------------- Python binding */

#define NBUF 16

static PyObject *py_solve(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *objs[NBUF];
    double mu_c, dmu, alpha, sc4, sc5, sc6, radius, ftol, xtol, gtol, predicted_ftol;
    int max_iterations, max_rejections;
    PyObject *cache = Py_None;
    if (!PyArg_ParseTuple(args, "OOOOOOOOOOOOOOOO(dddddd)diddddi|O:solve",
                          &objs[0], &objs[1], &objs[2], &objs[3], &objs[4], &objs[5], &objs[6], &objs[7],
                          &objs[8], &objs[9], &objs[10], &objs[11], &objs[12], &objs[13], &objs[14], &objs[15],
                          &mu_c, &dmu, &alpha, &sc4, &sc5, &sc6, &radius, &max_iterations, &ftol, &xtol,
                          &gtol, &predicted_ftol, &max_rejections, &cache))
        return NULL;
    static const char *names[NBUF] = {"pow_lam_v", "stiff", "lam_v", "mu", "wheel", "sw", "x", "lb", "ub",
                                      "prior", "inv_prior_std", "tie", "gradient", "normal", "r_data", "r_work"};
    Buf b[NBUF + 2];
    memset(b, 0, sizeof b);
    PyObject *result = NULL;
    double *rows_trial = NULL;
    Py_ssize_t m = -1, cached_n = 0;
    for (int i = 0; i < NBUF; i++) {
        Py_ssize_t count = -1;
        if (i >= 1 && i <= 5)
            count = m;
        else if (i >= 6 && i <= 10)
            count = NP;
        else if (i == 11)
            count = NT * NW;
        else if (i == 12)
            count = NP;
        else if (i == 13)
            count = NP * NP;
        const int writable = i == 6 || i >= 12;
        if (get_array(objs[i], &b[i], names[i], count, writable, i == 4) < 0)
            goto out;
        if (i == 0)
            m = b[0].view.len / 8;
        if (i >= 14 && b[i].view.len / 8 < m) {
            PyErr_Format(PyExc_ValueError, "%s: needs room for %zd values", names[i], m);
            goto out;
        }
    }
    const Py_ssize_t *wheel = (const Py_ssize_t *)b[4].view.buf;
    for (Py_ssize_t j = 0; j < m; j++)
        if (wheel[j] < 0 || wheel[j] >= NW) {
            PyErr_SetString(PyExc_ValueError, "wheel: index outside 0..3");
            goto out;
        }
    if (max_iterations < 0 || max_rejections < 1 || sc4 == 0 || sc5 == 0) {
        PyErr_SetString(PyExc_ValueError, "bad solver settings");
        goto out;
    }
    /* cache: (rows, rows_x, cached_n) — the window's unweighted rows (m x ROW, kept between
     * calls), the point they were computed at, and how many leading samples are valid there.
     * Without it the rows live in a buffer of this call's own, beside the trial's. */
    double *rows = NULL;
    const double *rows_x = NULL;
    if (cache != Py_None) {
        PyObject *o_rows, *o_x;
        if (!PyArg_ParseTuple(cache, "OOn:cache", &o_rows, &o_x, &cached_n))
            goto out;
        if (get_array(o_rows, &b[NBUF], "rows", m * ROW, 1, 0) < 0 || get_array(o_x, &b[NBUF + 1], "rows_x", NP, 0, 0) < 0)
            goto out;
        if (cached_n < 0 || cached_n > m) {
            PyErr_SetString(PyExc_ValueError, "cached_n: outside the window");
            goto out;
        }
        rows = b[NBUF].view.buf;
        rows_x = b[NBUF + 1].view.buf;
    }
    rows_trial = PyMem_Malloc((size_t)(ROW * m * (rows ? 1 : 2) + 1) * sizeof(double));
    if (!rows_trial) {
        PyErr_NoMemory();
        goto out;
    }
    if (!rows)
        rows = rows_trial + ROW * m;
    Problem p = {m, b[0].view.buf, b[1].view.buf, b[2].view.buf, b[3].view.buf, b[5].view.buf, wheel,
                 b[9].view.buf, b[10].view.buf, b[11].view.buf, mu_c, dmu, alpha, sc4, sc5, sc6};
    /* The GIL stays held: tens of microseconds, and a release would let the daemon's other
     * threads (or a test bench's sender) in mid-update, adding their time to the latency. */
    const Outcome o = solve(&p, b[6].view.buf, b[7].view.buf, b[8].view.buf, radius, max_iterations, ftol, xtol,
                            gtol, max_rejections, predicted_ftol, b[12].view.buf, b[13].view.buf, b[14].view.buf,
                            b[15].view.buf, rows, rows_x, cached_n, rows_trial);
    result = Py_BuildValue("(ddiOi)", o.cost, o.radius, o.iterations, o.converged ? Py_True : Py_False,
                           o.evaluations);
out:
    PyMem_Free(rows_trial);
    release_all(b, NBUF + 2);
    return result;
}

/* ---------------------------------------------- peaks and partials at a handful of points */

#define MAX_MODEL_SLIP 0.98   /* tyre_model.MAX_MODEL_SLIP */

/* tyre_model._peaks_near: parabolic steps around each previous peak slip; None when some
 * peak is not bracketed (the caller then searches the grid). */
static PyObject *py_peaks_near(PyObject *self, PyObject *args)
{
    (void)self;
    double v, mu_c, dmu, alpha, sigma0, theta_k, v_s, sigma2, thetas[MAX_POINTS], near[MAX_POINTS];
    PyObject *theta_obj, *near_obj;
    if (!PyArg_ParseTuple(args, "dOO(ddddddd):peaks_near", &v, &theta_obj, &near_obj, &mu_c, &dmu, &alpha,
                          &sigma0, &theta_k, &v_s, &sigma2))
        return NULL;
    const Py_ssize_t n = floats(theta_obj, thetas, "thetas");
    if (n < 0)
        return NULL;
    const Py_ssize_t n_near = floats(near_obj, near, "near");
    if (n_near < 0)
        return NULL;
    const double v_ratio = v / v_s, s2v = sigma2 * v, low = 2e-3, high = 0.9 * MAX_MODEL_SLIP;
    if (n_near != n || !(v_ratio > 0 && isfinite(v_ratio)))
        Py_RETURN_NONE;
    double mus[MAX_POINTS], lams[MAX_POINTS];
#define MU_AT(lam_, theta_, out_)                                                           \
    do {                                                                                    \
        const double g_ = mu_c + dmu * exp(-pow((lam_) * v_ratio, alpha));                  \
        double Z_ = ((theta_) * theta_k) * (lam_) / (g_ * (1.0 - (lam_)));                  \
        if (Z_ < SMALL_Z)                                                                   \
            Z_ = SMALL_Z;                                                                   \
        (out_) = (g_ / (theta_)) * (1.0 + expm1(-Z_) / Z_) + s2v * (lam_);                  \
    } while (0)
    for (Py_ssize_t i = 0; i < n; i++) {
        const double theta = thetas[i];
        double lam = fmin(fmax(near[i], low), high);
        const double steps[2] = {0.08, 0.02};
        for (int k = 0; k < 2; k++) {
            const double h = steps[k] * lam;
            double y0, y1, y2;
            MU_AT(lam - h, theta, y0);
            MU_AT(lam, theta, y1);
            MU_AT(lam + h, theta, y2);
            const double denom = y0 - 2 * y1 + y2;
            if (!(denom < 0 && y1 >= y0 && y1 >= y2))
                Py_RETURN_NONE;
            const double shift = 0.5 * (y0 - y2) / denom;
            lam = lam + shift * h;
            if (fabs(shift) <= 0.25)
                break;
        }
        MU_AT(lam, theta, mus[i]);
        if (!isfinite(mus[i]) || !isfinite(lam))
            Py_RETURN_NONE;
        lams[i] = lam;
    }
#undef MU_AT
    return pair_of(mus, n, lams, n);
}

/* tyre_model._mu_grid at one point (same order of operations). */
static double mu_grid_one(double lam, double v, double theta, double mu_c, double dmu, double alpha, double theta_k,
                          double v_s, double sigma2)
{
    const double g = mu_c + dmu * exp(-pow(lam * (v / v_s), alpha));
    double Z = (theta * theta_k) * lam / (g * (1.0 - lam));
    if (!(Z >= SMALL_Z))
        Z = Z != Z ? Z : SMALL_Z;   /* np.maximum: NaN stays NaN */
    return (g / theta) * (1.0 + expm1(-Z) / Z) + (sigma2 * v) * lam;
}

/* tyre_model.peaks without `near`: the first local maximum on the coarse slip grid, a fine grid
 * around it, and a parabola through the best fine point and its neighbours. */
static PyObject *py_peaks_grid(PyObject *self, PyObject *args)
{
    (void)self;
    double v, mu_c, dmu, alpha, sigma0, theta_k, v_s, sigma2, thetas[MAX_POINTS];
    PyObject *theta_obj, *o_grid, *o_fine;
    if (!PyArg_ParseTuple(args, "dOOO(ddddddd):peaks_grid", &v, &theta_obj, &o_grid, &o_fine, &mu_c, &dmu, &alpha,
                          &sigma0, &theta_k, &v_s, &sigma2))
        return NULL;
    const Py_ssize_t n = floats(theta_obj, thetas, "thetas");
    if (n < 0)
        return NULL;
    Buf b[2];
    memset(b, 0, sizeof b);
    PyObject *result = NULL;
    if (get_array(o_grid, &b[0], "grid", -1, 0, 0) < 0 || get_array(o_fine, &b[1], "fine", -1, 0, 0) < 0)
        goto out;
    const double *grid = b[0].view.buf, *fine_rel = b[1].view.buf;
    const Py_ssize_t ng = b[0].view.len / 8, nf = b[1].view.len / 8;
    if (ng < 3 || nf < 3 || ng > 256 || nf > 256) {
        PyErr_SetString(PyExc_ValueError, "grid and fine: 3 to 256 points");
        goto out;
    }
    double mus[MAX_POINTS], lams[MAX_POINTS], values[256], fine[256], fv[256];
    for (Py_ssize_t w = 0; w < n; w++) {
        const double th = thetas[w];
        for (Py_ssize_t k = 0; k < ng; k++)
            values[k] = mu_grid_one(grid[k], v, th, mu_c, dmu, alpha, theta_k, v_s, sigma2);
        /* The tyre's peak is the first local maximum (np.argmax of the first fall). */
        Py_ssize_t i = ng - 1;
        for (Py_ssize_t k = 0; k + 1 < ng; k++)
            if (values[k + 1] - values[k] < 0) {
                i = k;
                break;
            }
        const double lo = grid[i > 0 ? i - 1 : 0], hi = grid[i + 1 < ng ? i + 1 : ng - 1], centre = grid[i];
        const double half = fmax(centre - lo, hi - centre);
        Py_ssize_t j = 0;
        for (Py_ssize_t k = 0; k < nf; k++) {
            fine[k] = fmin(fmax(centre + half * fine_rel[k], 1e-4), MAX_MODEL_SLIP);
            fv[k] = mu_grid_one(fine[k], v, th, mu_c, dmu, alpha, theta_k, v_s, sigma2);
            if (fv[j] == fv[j] && (fv[k] != fv[k] || fv[k] > fv[j]))
                j = k;   /* np.argmax: the first maximum, a NaN counting as one */
        }
        /* _refine */
        if (j < 1)
            j = 1;
        if (j > nf - 2)
            j = nf - 2;
        const double y0 = fv[j - 1], y1 = fv[j], y2 = fv[j + 1], x1 = fine[j], h = fine[j + 1] - x1;
        const double denom = y0 - 2 * y1 + y2;
        double shift = denom < 0 ? 0.5 * (y0 - y2) / denom : 0.0;
        shift = fmin(fmax(shift, -1.0), 1.0);
        const double lam_star = fmin(fmax(x1 + shift * h, 1e-4), MAX_MODEL_SLIP);
        const double mu_star = mu_grid_one(lam_star, v, th, mu_c, dmu, alpha, theta_k, v_s, sigma2);
        mus[w] = mu_star != mu_star || y1 != y1 ? NAN : fmax(mu_star, y1);
        lams[w] = lam_star;
    }
    result = pair_of(mus, n, lams, n);
out:
    release_all(b, 2);
    return result;
}

/* μ and the four partials at (λ, θ), one speed (tyre_model.braking_mu_and_partials_few for one
 * point, same operations); c = (mu_c, dmu, alpha, sigma0, sigma0·L, v_s, sigma2). */
static double mu_partials_one(double lam, double v, double theta, const double *c, double *row)
{
    const double mu_c = c[0], dmu = c[1], alpha = c[2], sigma0 = c[3], k = c[4], v_s = c[5], sigma2 = c[6];
    lam = fmin(lam, MAX_MODEL_SLIP);
    const double lam_v = lam * v;
    const double ratio = lam_v >= 0 ? pow(lam_v * (1.0 / v_s), alpha) : NAN;
    const double e = exp(-ratio), g = mu_c + dmu * e, inv_theta = 1.0 / theta;
    const double Z = theta * k * lam / (g * (1.0 - lam));
    double F, dF;
    if (Z < SMALL_Z) {
        F = Z / 2.0 - Z * Z / 6.0;
        dF = 0.5 - Z / 3.0;
    } else {
        const double one_minus = -expm1(-Z), inv_Z = 1.0 / Z;
        F = 1.0 - one_minus * inv_Z;
        dF = (one_minus - Z * exp(-Z)) * inv_Z * inv_Z;
    }
    const double g_over_theta = g * inv_theta, ZdF = Z * dF;
    if (row) {
        row[0] = g_over_theta * inv_theta * (ZdF - F);
        row[1] = g_over_theta * ZdF * (1.0 / sigma0);
        row[2] = (F - ZdF) * inv_theta * dmu * e * (alpha / v_s) * ratio;
        row[3] = lam_v;
    }
    return g_over_theta * F + sigma2 * lam_v;
}

/* tyre_model.braking_mu_and_partials_few: μ and ∂μ/∂(θ, σ0, v_s, σ2) at (λ_i, θ_i), one speed. */
static PyObject *py_mu_partials_few(PyObject *self, PyObject *args)
{
    (void)self;
    double v, mu_c, dmu, alpha, sigma0, k, v_s, sigma2, lams[MAX_POINTS], thetas[MAX_POINTS];
    PyObject *lam_obj, *theta_obj;
    if (!PyArg_ParseTuple(args, "OdO(ddddddd):mu_partials_few", &lam_obj, &v, &theta_obj, &mu_c, &dmu, &alpha,
                          &sigma0, &k, &v_s, &sigma2))
        return NULL;
    const Py_ssize_t n = floats(lam_obj, lams, "lam");
    if (n < 0)
        return NULL;
    if (floats(theta_obj, thetas, "theta") != n) {
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_ValueError, "lam and theta differ in length");
        return NULL;
    }
    const double c[7] = {mu_c, dmu, alpha, sigma0, k, v_s, sigma2};
    double mus[MAX_POINTS], rows[4 * MAX_POINTS];
    for (Py_ssize_t i = 0; i < n; i++)
        mus[i] = mu_partials_one(lams[i], v, thetas[i], c, rows + 4 * i);
    return pair_of(mus, n, rows, 4 * n);
}

/* ------------------------------------------------------------ per-wheel statistics */


/* numpy's float "less than": NaN is the largest. */
static inline int npy_less(double a, double b) { return a < b || (b != b && a == a); }

static int cmp_double(const void *a, const void *b)
{
    const double x = *(const double *)a, y = *(const double *)b;
    return npy_less(y, x) - npy_less(x, y);
}

/* Ascending in numpy's order (NaN last). A wheel's recent samples are a few dozen: insertion
 * sort there, without qsort's call per comparison (most of the excitation's cost before). */
static void sort_values(double *v, Py_ssize_t n)
{
    if (n > 64) {
        qsort(v, (size_t)n, sizeof(double), cmp_double);
        return;
    }
    for (Py_ssize_t i = 1; i < n; i++) {
        const double x = v[i];
        Py_ssize_t k = i;
        for (; k > 0 && npy_less(x, v[k - 1]); k--)
            v[k] = v[k - 1];
        v[k] = x;
    }
}

/* numpy's linear quantile of sorted values (its lerp, the same on both sides of 1/2). */
static double quantile_sorted(const double *v, Py_ssize_t n, double q)
{
    const double virtual_index = (n - 1) * q;
    Py_ssize_t i = (Py_ssize_t)floor(virtual_index);
    if (i > n - 1)
        i = n - 1;
    const double t = virtual_index - i;
    if (i >= n - 1)
        return v[n - 1];
    const double a = v[i], b = v[i + 1], diff = b - a;
    return t >= 0.5 ? b - diff * (1 - t) : a + diff * t;
}

#define N_STATS 12

/* Per wheel, over the samples given (time order): n; the 10 % and 90 % slip quantiles; the
 * slips and μ of order k_lo, k_hi (k = n // 10 from each end, as the excitation test takes
 * them); the fastest slip run-away over `lag` samples whose force did not follow; the sums
 * of the through-origin quadratic fit. estimator._wheel_stats_numpy is the reference. */

/* numpy's a[lo:hi].searchsorted(t, side="left") + lo: the first k with a[k] >= t (NaN sorts last). */
static Py_ssize_t search_left(const double *a, Py_ssize_t lo, Py_ssize_t hi, double t)
{
    while (lo < hi) {
        const Py_ssize_t mid = lo + (hi - lo) / 2;
        if (npy_less(a[mid], t))
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}

/* numpy's a[lo:hi].searchsorted(t, side="right") + lo: the first k with a[k] > t. */
static Py_ssize_t search_right(const double *a, Py_ssize_t lo, Py_ssize_t hi, double t)
{
    while (lo < hi) {
        const Py_ssize_t mid = lo + (hi - lo) / 2;
        if (npy_less(t, a[mid]))
            hi = mid;
        else
            lo = mid + 1;
    }
    return lo;
}

/* estimator._wheel_stats_numpy over m samples: a tuple of four 12-tuples (NULL with an exception). */
static PyObject *wheel_stats_of(const double *slip, const double *mu, const Py_ssize_t *wheel, const double *times,
                                Py_ssize_t m, int lag, double elasticity)
{
    if (lag < 1) {
        PyErr_SetString(PyExc_ValueError, "lag: must be >= 1");
        return NULL;
    }
    double *work = PyMem_Malloc((size_t)(4 * (m + 1)) * sizeof(double));
    if (!work)
        return PyErr_NoMemory();
    double *lam = work, *mus = work + (m + 1), *ts = work + 2 * (m + 1), *sorted = work + 3 * (m + 1);
    PyObject *result = PyTuple_New(NW);
    if (!result)
        goto out;
    for (int w = 0; w < NW; w++) {
        Py_ssize_t n = 0;
        double s2 = 0, s3 = 0, s4 = 0, y1 = 0, y2 = 0;
        for (Py_ssize_t j = 0; j < m; j++) {
            if (wheel[j] != w)
                continue;
            const double l = slip[j], l2 = l * l;
            lam[n] = l;
            mus[n] = mu[j];
            ts[n] = times[j];
            s2 += l2;
            s3 += l2 * l;
            s4 += l2 * l2;
            y1 += l * mu[j];
            y2 += l2 * mu[j];
            n++;
        }
        double stats[N_STATS];
        for (int k = 0; k < N_STATS; k++)
            stats[k] = NAN;
        stats[0] = (double)n;
        if (n > 0) {
            memcpy(sorted, lam, n * sizeof(double));
            sort_values(sorted, n);
            stats[1] = quantile_sorted(sorted, n, 0.1);
            stats[2] = quantile_sorted(sorted, n, 0.9);
            Py_ssize_t k_hi = n - 1 - (n / 10 > 1 ? n / 10 : 1), k_lo = n / 10 > 1 ? n / 10 : 1;
            if (k_hi < 0)
                k_hi = 0;
            if (k_lo > n - 1)
                k_lo = n - 1;
            stats[3] = sorted[k_lo];
            stats[4] = sorted[k_hi];
            memcpy(sorted, mus, n * sizeof(double));
            sort_values(sorted, n);
            stats[5] = sorted[k_hi];
            double best = -INFINITY;
            for (Py_ssize_t j = 0; j + lag < n; j++) {
                const double d_lam = lam[j + lag] - lam[j];
                double rate = d_lam / fmax(ts[j + lag] - ts[j], 1e-3);
                if ((mus[j + lag] - mus[j]) * lam[j] > elasticity * d_lam * mus[j])
                    rate = 0.0;   /* the force follows the slip: not a run-away */
                if (rate != rate) {
                    best = NAN;
                    break;
                }
                best = rate > best ? rate : best;
            }
            stats[6] = best;
        }
        stats[7] = s2;
        stats[8] = s3;
        stats[9] = s4;
        stats[10] = y1;
        stats[11] = y2;
        PyObject *t = tuple_of(stats, N_STATS);
        if (!t) {
            Py_CLEAR(result);
            goto out;
        }
        PyTuple_SET_ITEM(result, w, t);
    }
out:
    PyMem_Free(work);
    return result;
}

static PyObject *py_wheel_stats(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *objs[4];
    int lag;
    double elasticity;
    if (!PyArg_ParseTuple(args, "OOOOid:wheel_stats", &objs[0], &objs[1], &objs[2], &objs[3], &lag, &elasticity))
        return NULL;
    static const char *names[4] = {"slip", "mu", "wheel", "times"};
    Buf b[4];
    memset(b, 0, sizeof b);
    PyObject *result = NULL;
    Py_ssize_t m = -1;
    for (int i = 0; i < 4; i++) {
        if (get_array(objs[i], &b[i], names[i], m, 0, i == 2) < 0)
            goto out;
        if (i == 0)
            m = b[0].view.len / 8;
    }
    result = wheel_stats_of(b[0].view.buf, b[1].view.buf, b[2].view.buf, b[3].view.buf, m, lag, elasticity);
out:
    release_all(b, 4);
    return result;
}

/* recent_wheel_stats(slip, columns, lo, hi, threshold, lag, elasticity) -> wheel_stats of the window's
 * samples [k, hi) whose forgetting weight (fit_window's, scratch row 2) exceeds `threshold`, k found
 * as numpy's weights[lo:hi].searchsorted(threshold, side="right"); columns as fit_window's. */
static PyObject *py_recent_wheel_stats(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *o_slip, *columns;
    Py_ssize_t lo, hi;
    double threshold, elasticity;
    int lag;
    if (!PyArg_ParseTuple(args, "OO!nndid:recent_wheel_stats", &o_slip, &PyTuple_Type, &columns, &lo, &hi, &threshold,
                          &lag, &elasticity))
        return NULL;
    if (PyTuple_GET_SIZE(columns) != 8) {
        PyErr_SetString(PyExc_ValueError, "recent_wheel_stats: columns are fit_window's 8");
        return NULL;
    }
    Buf b[5];
    memset(b, 0, sizeof b);
    PyObject *result = NULL;
    if (get_array(o_slip, &b[0], "slip", -1, 0, 0) < 0)
        goto out;
    const Py_ssize_t cap = b[0].view.len / 8;
    if (get_array(PyTuple_GET_ITEM(columns, 3), &b[1], "mu", cap, 0, 0) < 0
        || get_array(PyTuple_GET_ITEM(columns, 4), &b[2], "wheel", cap, 0, 1) < 0
        || get_array(PyTuple_GET_ITEM(columns, 5), &b[3], "time", cap, 0, 0) < 0
        || get_array(PyTuple_GET_ITEM(columns, 6), &b[4], "scratch", 4 * cap, 0, 0) < 0)
        goto out;
    if (lo < 0 || hi < lo || hi > cap) {
        PyErr_SetString(PyExc_ValueError, "recent_wheel_stats: lo, hi outside the window");
        goto out;
    }
    /* the first weight beyond the threshold (fit_window's weights: scratch row 2) */
    const Py_ssize_t k = search_right((const double *)b[4].view.buf + 2 * cap, lo, hi, threshold);
    result = wheel_stats_of((const double *)b[0].view.buf + k, (const double *)b[1].view.buf + k,
                            (const Py_ssize_t *)b[2].view.buf + k, (const double *)b[3].view.buf + k, hi - k, lag,
                            elasticity);
out:
    release_all(b, 5);
    return result;
}

/* estimator._data_peaks's statistics: per wheel, its samples [lo, hi) in slip order (ties in time
 * order, as numpy's stable sort), in groups of k; each group's mean less twice its standard error
 * (sample standard deviation, ddof 1); the highest, times (1 - margin), not below 0; 0 for a wheel
 * with fewer than max(k, min_n) samples. */
typedef struct {
    double slip;
    Py_ssize_t at;
} SlipAt;

static int slip_at_order(const void *a, const void *b)
{
    const SlipAt *x = a, *y = b;
    if (x->slip < y->slip)
        return -1;
    if (x->slip > y->slip)
        return 1;
    return (x->at > y->at) - (x->at < y->at);
}

/* The window's slip, μ and wheel columns into b[0..2] (the same capacity); their capacity, or -1
 * with an exception. */
static Py_ssize_t get_slip_mu_wheel(PyObject *o_slip, PyObject *o_mu, PyObject *o_wheel, Buf *b)
{
    if (get_array(o_slip, &b[0], "slip", -1, 0, 0) < 0)
        return -1;
    const Py_ssize_t cap = b[0].view.len / 8;
    if (get_array(o_mu, &b[1], "mu", cap, 0, 0) < 0 || get_array(o_wheel, &b[2], "wheel", cap, 0, 1) < 0)
        return -1;
    return cap;
}

/* One value per wheel from a sequence into out; 0 with an exception ("<who>: one peak per wheel"). */
static int per_wheel(PyObject *o, double *out, const char *name, const char *who)
{
    if (floats(o, out, name) == NW)
        return 1;
    if (!PyErr_Occurred())
        PyErr_Format(PyExc_ValueError, "%s: one peak per wheel", who);
    return 0;
}

/* Sums and counts of values per band of a ratio between consecutive edges (band 0 below the
   first edge, the last past the last), in the order numpy's bincount adds them. */
typedef struct {
    double sums[MAX_POINTS + 1];
    Py_ssize_t counts[MAX_POINTS + 1];
} BandSums;

/* Adds value to the band of `at` (numpy.searchsorted(edges, at, side="right"): a NaN sorts past
   every edge). */
static void band_add(BandSums *acc, const double *edges, Py_ssize_t n_edges, double at, double value)
{
    Py_ssize_t band = 0;
    if (isnan(at))
        band = n_edges;
    else
        while (band < n_edges && edges[band] <= at)
            band++;
    acc->sums[band] += value;
    acc->counts[band]++;
}

/* The highest band mean over the bands [first, last] with min_n values or more, as numpy's max
   over them (a NaN mean wins); *found: whether any band had them. */
static double highest_band_mean(const BandSums *acc, Py_ssize_t first, Py_ssize_t last, Py_ssize_t min_n, int *found)
{
    double best = 0.0;
    *found = 0;
    for (Py_ssize_t k = first; k <= last; k++)
        if (acc->counts[k] >= min_n) {
            const double mean = acc->sums[k] / (double)acc->counts[k];
            if (!*found || isnan(mean) || mean > best)
                best = *found && isnan(best) ? best : mean;
            *found = 1;
        }
    return best;
}

/* EstimateConfidence._band_ratio_of over the window's samples [lo, hi): per band of slips (as
   multiples of each wheel's peak slip, between consecutive edges), the mean of μ over the wheel's
   peak μ; the highest of the bands with min_n samples or more, 0 without any. The same sums in
   the same order as numpy's bincount. */
static PyObject *py_band_ratio(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *o_slip, *o_mu, *o_wheel, *o_peak_mu, *o_peak_slip, *o_edges;
    Py_ssize_t lo, hi, min_n;
    if (!PyArg_ParseTuple(args, "OOOnnOOOn:band_ratio", &o_slip, &o_mu, &o_wheel, &lo, &hi, &o_peak_mu, &o_peak_slip,
                          &o_edges, &min_n))
        return NULL;
    double peak_mu[MAX_POINTS], peak_slip[MAX_POINTS], edges[MAX_POINTS];
    if (!per_wheel(o_peak_mu, peak_mu, "peak_mu", "band_ratio") || !per_wheel(o_peak_slip, peak_slip, "peak_slip", "band_ratio"))
        return NULL;
    const Py_ssize_t n_edges = floats(o_edges, edges, "edges");
    if (n_edges < 0)
        return NULL;
    Buf b[3];
    memset(b, 0, sizeof b);
    PyObject *result = NULL;
    const Py_ssize_t cap = get_slip_mu_wheel(o_slip, o_mu, o_wheel, b);
    if (cap < 0)
        goto out;
    if (lo < 0 || hi < lo || hi > cap) {
        PyErr_SetString(PyExc_ValueError, "band_ratio: lo, hi outside the window");
        goto out;
    }
    const double *slip = b[0].view.buf, *mu = b[1].view.buf;
    const Py_ssize_t *wheel = b[2].view.buf;
    for (int w = 0; w < NW; w++) {
        peak_mu[w] = py_max(peak_mu[w], 1e-3);
        peak_slip[w] = py_max(peak_slip[w], 1e-3);
    }
    BandSums acc;
    memset(&acc, 0, sizeof acc);
    for (Py_ssize_t j = lo; j < hi; j++) {
        const Py_ssize_t w = wheel[j];
        if (w >= 0 && w < NW)
            band_add(&acc, edges, n_edges, slip[j] / peak_slip[w], mu[j] / peak_mu[w]);
    }
    int found;
    const double best = highest_band_mean(&acc, 1, n_edges - 1, min_n, &found);
    result = PyFloat_FromDouble(found ? best : 0.0);
out:
    release_all(b, 3);
    return result;
}


/* excess_over_fit(scratch, slip, wheel, lo, hi, wheel_mu, fitted_mu, peak_slip, edges, min_n) -> float:
   EstimateConfidence._excess_over_fit over the window's samples [lo, hi). scratch: the window's
   (4, capacity) scratch, row 0 the weighted model − data, row 3 the weights. Per band of slips
   (multiples of each wheel's peak slip; band 0 below the first edge never counts), the mean of
   (data − model − lift) / published peak (published: wheel_mu, at least 1e-3; the lift: that
   less fitted_mu); the highest over bands of min_n samples or more, at least 0. The same sums in the same order as numpy's bincount. */
static PyObject *py_excess_over_fit(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *o_scratch, *o_slip, *o_wheel, *o_published, *o_lift, *o_peak_slip, *o_edges;
    Py_ssize_t lo, hi, min_n;
    if (!PyArg_ParseTuple(args, "OOOnnOOOOn:excess_over_fit", &o_scratch, &o_slip, &o_wheel, &lo, &hi,
                          &o_published, &o_lift, &o_peak_slip, &o_edges, &min_n))
        return NULL;
    double published[MAX_POINTS], lift[MAX_POINTS], peak_slip[MAX_POINTS], edges[MAX_POINTS];
    const char *who = "excess_over_fit";
    if (!per_wheel(o_published, published, "wheel_mu", who) || !per_wheel(o_lift, lift, "fitted_mu", who)
        || !per_wheel(o_peak_slip, peak_slip, "peak_slip", who))
        return NULL;
    const Py_ssize_t n_edges = floats(o_edges, edges, "edges");
    Buf b[3];
    if (n_edges < 0)
        return NULL;
    memset(b, 0, sizeof b);
    PyObject *result = NULL;
    if (get_array(o_scratch, &b[0], "scratch", -1, 0, 0) < 0 || get_array(o_slip, &b[1], "slip", -1, 0, 0) < 0
        || get_array(o_wheel, &b[2], "wheel", -1, 0, 1) < 0)
        goto out;
    const Py_ssize_t cap = b[1].view.len / 8;
    if (b[0].view.len / 8 != 4 * cap || b[2].view.len / (Py_ssize_t)sizeof(Py_ssize_t) != cap) {
        PyErr_SetString(PyExc_ValueError, "excess_over_fit: scratch must be (4, capacity), wheel (capacity,)");
        goto out;
    }
    if (lo < 0 || hi < lo || hi > cap) {
        PyErr_SetString(PyExc_ValueError, "excess_over_fit: lo, hi outside the window");
        goto out;
    }
    const double *model_minus_weighted = b[0].view.buf, *weights = model_minus_weighted + 3 * cap;
    const double *slip = b[1].view.buf;
    const Py_ssize_t *wheel = b[2].view.buf;
    for (int w = 0; w < NW; w++) {
        peak_slip[w] = py_max(peak_slip[w], 1e-3);
        published[w] = py_max(published[w], 1e-3);
        lift[w] = published[w] - lift[w];
    }
    BandSums acc;
    memset(&acc, 0, sizeof acc);
    for (Py_ssize_t j = lo; j < hi; j++) {
        const Py_ssize_t w = wheel[j];
        if (w < 0 || w >= NW)
            continue;
        const double model_minus_data = weights[j] > 0.0 ? model_minus_weighted[j] / weights[j] : 0.0;
        band_add(&acc, edges, n_edges, slip[j] / peak_slip[w], (-model_minus_data - lift[w]) / published[w]);
    }
    int found;
    const double best = highest_band_mean(&acc, 1, n_edges, min_n, &found);
    result = PyFloat_FromDouble(found && best > 0.0 ? best : 0.0);
out:
    release_all(b, 3);
    return result;
}

static PyObject *py_data_peaks(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *o_slip, *o_mu, *o_wheel;
    Py_ssize_t lo, hi, min_n;
    int k;
    double margin;
    if (!PyArg_ParseTuple(args, "OOOnnind:data_peaks", &o_slip, &o_mu, &o_wheel, &lo, &hi, &k, &min_n, &margin))
        return NULL;
    Buf b[3];
    memset(b, 0, sizeof b);
    PyObject *result = NULL;
    SlipAt *order = NULL;
    const Py_ssize_t cap = get_slip_mu_wheel(o_slip, o_mu, o_wheel, b);
    if (cap < 0)
        goto out;
    if (lo < 0 || hi < lo || hi > cap || k < 2) {
        PyErr_SetString(PyExc_ValueError, "data_peaks: lo, hi outside the window, or k < 2");
        goto out;
    }
    const double *slip = b[0].view.buf, *mu = b[1].view.buf;
    const Py_ssize_t *wheel = b[2].view.buf;
    order = PyMem_Malloc(sizeof(SlipAt) * (size_t)(hi - lo + 1));
    if (!order) {
        PyErr_NoMemory();
        goto out;
    }
    double out[NW];
    for (int w = 0; w < NW; w++) {
        Py_ssize_t n = 0;
        for (Py_ssize_t j = lo; j < hi; j++)
            if (wheel[j] == w) {
                order[n].slip = slip[j];
                order[n].at = j;
                n++;
            }
        out[w] = 0.0;
        if (n < (k > min_n ? k : min_n))
            continue;
        qsort(order, (size_t)n, sizeof(SlipAt), slip_at_order);
        double best = -INFINITY;
        for (Py_ssize_t g = 0; g + k <= n; g += k) {
            double sum = 0.0;
            for (int i = 0; i < k; i++)
                sum += mu[order[g + i].at];
            const double mean = sum / k;
            double ss = 0.0;
            for (int i = 0; i < k; i++) {
                const double d = mu[order[g + i].at] - mean;
                ss += d * d;
            }
            const double lower = mean - 2.0 * sqrt(ss / (k - 1)) / sqrt((double)k);
            if (lower > best)
                best = lower;
        }
        out[w] = best * (1.0 - margin) > 0.0 ? best * (1.0 - margin) : 0.0;
    }
    result = Py_BuildValue("[dddd]", out[0], out[1], out[2], out[3]);
out:
    PyMem_Free(order);
    release_all(b, 3);
    return result;
}

/* μ alone at (λ, θ) (mu_partials_one's value; √ for the usual α = ½, the same to rounding). */
static double mu_one(double lam, double v, double theta, const double *c)
{
    const double mu_c = c[0], dmu = c[1], alpha = c[2], k = c[4], v_s = c[5], sigma2 = c[6];
    lam = fmin(lam, MAX_MODEL_SLIP);
    const double lam_v = lam * v;
    const double ratio = lam_v >= 0 ? (alpha == 0.5 ? sqrt(lam_v / v_s) : pow(lam_v * (1.0 / v_s), alpha)) : NAN;
    const double g = mu_c + dmu * exp(-ratio);
    const double Z = theta * k * lam / (g * (1.0 - lam));
    const double F = Z < SMALL_Z ? Z / 2.0 - Z * Z / 6.0 : 1.0 + expm1(-Z) / Z;
    return g / theta * F + sigma2 * lam_v;
}

/* estimator._spread_loss_numpy: over the window's samples [lo, hi) with a spread of slips (rows 2
 * and 3 of `spread` not both 0; rows 0, 1 the slips at the filter window's ends), the share of
 * the fitted μ at a sample's slip that the filter's mean over its spread loses, averaged over the
 * samples at the top of their wheel's data (μ within 10 % of the wheel's highest, wheels with 3
 * samples or more); 0 when there are none or the mean is not above 0. */
static PyObject *py_spread_loss(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *o_slip, *o_speed, *o_mu, *o_wheel, *o_spread, *theta_obj;
    Py_ssize_t lo, hi;
    double mu_c, dmu, alpha, sigma0, k, v_s, sigma2, thetas[MAX_POINTS];
    if (!PyArg_ParseTuple(args, "OOOOOnnO(ddddddd):spread_loss", &o_slip, &o_speed, &o_mu, &o_wheel, &o_spread, &lo,
                          &hi, &theta_obj, &mu_c, &dmu, &alpha, &sigma0, &k, &v_s, &sigma2))
        return NULL;
    if (floats(theta_obj, thetas, "thetas") != NW) {
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_ValueError, "spread_loss: one theta per wheel");
        return NULL;
    }
    Buf b[5];
    memset(b, 0, sizeof b);
    PyObject *result = NULL;
    const Py_ssize_t cap = get_slip_mu_wheel(o_slip, o_mu, o_wheel, b);
    if (cap < 0 || get_array(o_speed, &b[3], "speed", cap, 0, 0) < 0
        || get_array(o_spread, &b[4], "spread", 4 * cap, 0, 0) < 0)
        goto out;
    if (lo < 0 || hi < lo || hi > cap) {
        PyErr_SetString(PyExc_ValueError, "spread_loss: lo, hi outside the window");
        goto out;
    }
    const double *slip = b[0].view.buf, *mu = b[1].view.buf, *speed = b[3].view.buf, *spread = b[4].view.buf;
    const Py_ssize_t *wheel = b[2].view.buf;
    const double *s_lo = spread, *s_hi = spread + cap, *a_lo = spread + 2 * cap, *a_hi = spread + 3 * cap;
    const double c[7] = {mu_c, dmu, alpha, sigma0, k, v_s, sigma2};
    double top[NW];
    Py_ssize_t count[NW] = {0, 0, 0, 0};
    for (int w = 0; w < NW; w++)
        top[w] = -INFINITY;
    for (Py_ssize_t j = lo; j < hi; j++)
        if (a_lo[j] + a_hi[j] > 0.0 && wheel[j] >= 0 && wheel[j] < NW) {
            count[wheel[j]]++;
            if (mu[j] > top[wheel[j]])
                top[wheel[j]] = mu[j];
        }
    double sum = 0.0;
    Py_ssize_t n = 0;
    for (Py_ssize_t j = lo; j < hi; j++) {
        if (!(a_lo[j] + a_hi[j] > 0.0) || wheel[j] < 0 || wheel[j] >= NW)
            continue;
        const Py_ssize_t w = wheel[j];
        if (count[w] < 3 || !(mu[j] >= 0.9 * top[w]))
            continue;
        const double theta = thetas[w], v = speed[j];
        const double centre = mu_one(slip[j], v, theta, c);
        const double loss = a_lo[j] * (centre - mu_one(s_lo[j], v, theta, c))
                            + a_hi[j] * (centre - mu_one(s_hi[j], v, theta, c));
        sum += loss / (centre > 0.05 ? centre : 0.05);
        n++;
    }
    const double share = n > 0 ? sum / (double)n : 0.0;
    result = PyFloat_FromDouble(share > 0.0 ? share : 0.0);
out:
    release_all(b, 5);
    return result;
}

/* ------------------------------------------------------------- the reported peak */


/* The reported numbers from the wheels' peaks (LugreTrustRegionEstimator._report_numbers_numpy):
 * each peak held within the slips the data support, the load-weighted μ_max, and by the delta
 * method the standard deviations of μ_max and of each wheel's peak. */
static PyObject *py_peak_report(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    PyObject *o_mu, *o_lam, *o_support, *o_floor, *o_thetas, *o_share, *o_cov;
    double extrapolation, extrapolation_max_slip, v, variance_factor, c[7], sc[3];
    /* (METH_FASTCALL: converted here, once per fit, without a format string) */
    if (!arg_count("peak_report", nargs, 13))
        return NULL;
    o_mu = args[0], o_lam = args[1], o_support = args[2], o_floor = args[3], o_thetas = args[6];
    o_cov = args[10], o_share = args[12];
    if (!arg_double(args[4], &extrapolation) || !arg_double(args[5], &extrapolation_max_slip)
        || !arg_double(args[7], &v) || !arg_doubles(args[8], c, 7, "params") || !arg_doubles(args[9], sc, 3, "scale")
        || !arg_double(args[11], &variance_factor))
        return NULL;
    double wheel_mu[MAX_POINTS], wheel_lam[MAX_POINTS], support[MAX_POINTS], slip_floor[MAX_POINTS],
        thetas[MAX_POINTS], share[MAX_POINTS];
    if (floats(o_mu, wheel_mu, "wheel_mu") != NW || floats(o_lam, wheel_lam, "wheel_lam") != NW ||
        floats(o_support, support, "support") != NW || floats(o_floor, slip_floor, "slip_floor") != NW ||
        floats(o_thetas, thetas, "thetas") != NW || floats(o_share, share, "share") != NW) {
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_ValueError, "peak_report: four values per wheel");
        return NULL;
    }
    Buf cb;
    memset(&cb, 0, sizeof cb);
    if (get_array(o_cov, &cb, "cov", NP * NP, 0, 0) < 0) {
        if (cb.held)
            PyBuffer_Release(&cb.view);
        return NULL;
    }
    double cov[NP * NP];
    memcpy(cov, cb.view.buf, sizeof cov);
    PyBuffer_Release(&cb.view);
    /* A wheel without recent samples is bounded by the slips its car-mates have seen. */
    int any_finite = 0, all_finite = 1;
    double finite_max = -INFINITY;
    for (int i = 0; i < NW; i++) {
        if (isfinite(support[i])) {
            any_finite = 1;
            finite_max = support[i] > finite_max ? support[i] : finite_max;
        } else
            all_finite = 0;
    }
    if (!all_finite && any_finite)
        for (int i = 0; i < NW; i++)
            if (!isfinite(support[i]))
                support[i] = finite_max;
    int capped[NW];
    double G[NW][NP], row[4];
    for (int i = 0; i < NW; i++) {
        const double cap = fmin(support[i] * extrapolation, fmax(support[i], extrapolation_max_slip));
        const double floor_i = slip_floor[i] / extrapolation;
        const int beyond = wheel_lam[i] > cap, below = wheel_lam[i] < floor_i;
        capped[i] = beyond || below;
        if (capped[i]) {
            const double limit = beyond ? cap : floor_i;
            const double mu_cap = mu_partials_one(limit, v, thetas[i], c, NULL);
            wheel_mu[i] = mu_cap < wheel_mu[i] ? mu_cap : wheel_mu[i];   /* np.minimum */
            if (mu_cap != mu_cap)
                wheel_mu[i] = mu_cap;
            wheel_lam[i] = limit;
        }
        /* Delta method: ∂μ_max/∂x at each wheel's peak (envelope theorem). */
        mu_partials_one(wheel_lam[i], v, thetas[i], c, row);
        for (int k = 0; k < NP; k++)
            G[i][k] = 0.0;
        G[i][i] = row[0] * thetas[i];
        G[i][NW] = row[1] * sc[0];
        G[i][NW + 1] = row[2] * sc[1];
        G[i][NW + 2] = row[3] * sc[2];
    }
    double mu_max = 0.0, slip_star = 0.0, g_mean[NP] = {0}, wheel_std[NW];
    for (int i = 0; i < NW; i++) {
        mu_max += share[i] * wheel_mu[i];
        slip_star += share[i] * wheel_lam[i];
        for (int k = 0; k < NP; k++)
            g_mean[k] += share[i] * G[i][k];
    }
    double var = 0.0;
    for (int a = 0; a < NP; a++)
        for (int b = 0; b < NP; b++)
            var += g_mean[a] * cov[a * NP + b] * variance_factor * g_mean[b];
    for (int i = 0; i < NW; i++) {
        double w = 0.0;
        for (int a = 0; a < NP; a++)
            for (int b = 0; b < NP; b++)
                w += G[i][a] * cov[a * NP + b] * variance_factor * G[i][b];
        wheel_std[i] = w == w ? sqrt(py_max(w, 0.0)) : w;
    }
    const double mu_std = sqrt(py_max(var, 0.0));
    PyObject *t_mu = tuple_of(wheel_mu, NW), *t_lam = tuple_of(wheel_lam, NW), *t_std = tuple_of(wheel_std, NW);
    PyObject *t_capped = PyTuple_New(NW);
    if (!t_mu || !t_lam || !t_std || !t_capped) {
        Py_XDECREF(t_mu);
        Py_XDECREF(t_lam);
        Py_XDECREF(t_std);
        Py_XDECREF(t_capped);
        return NULL;
    }
    for (int i = 0; i < NW; i++) {
        PyObject *flag = capped[i] ? Py_True : Py_False;
        Py_INCREF(flag);
        PyTuple_SET_ITEM(t_capped, i, flag);
    }
    return Py_BuildValue("(NNNdddN)", t_mu, t_lam, t_capped, mu_max, slip_star, mu_std, t_std);
}

/* ------------------------------------------------- weights, residual bias, covariance */

/* Forgetting weights exp(min(t − now, 0)/τ) and the rows' weights √w/σ of m samples; returns Σ w. */
static double weights_into(const double *t, Py_ssize_t m, double now, double tau, double sigma, double *w, double *sw)
{
    const double inv_sigma = 1.0 / sigma;
    double total = 0.0;
    for (Py_ssize_t j = 0; j < m; j++) {
        w[j] = exp(fmin(t[j] - now, 0.0) / tau);
        sw[j] = sqrt(w[j]) * inv_sigma;
        total += w[j];
    }
    return total;
}

/* The residuals r[first:m] back in μ units (r·σ/√w): their mean, rms deviation and |Σ sign| / n.
 * With `wheel`, only the front wheels' (index 0 or 1); returns how many were counted (0: all 0). */
static Py_ssize_t residual_stats(const double *r, const double *w, const Py_ssize_t *wheel, Py_ssize_t first,
                                 Py_ssize_t m, double sigma, double *mean, double *rms, double *same_sign)
{
    Py_ssize_t n = 0;
    double sum = 0.0, signs = 0.0;
    for (Py_ssize_t j = first; j < m; j++) {
        if (wheel && wheel[j] >= 2)
            continue;
        const double e = r[j] * sigma / sqrt(w[j]);
        sum += e;
        signs += (e > 0) - (e < 0);
        n++;
    }
    *mean = *rms = *same_sign = 0.0;
    if (n == 0)
        return 0;
    *mean = sum / n;
    double dev2 = 0.0;
    for (Py_ssize_t j = first; j < m; j++) {
        if (wheel && wheel[j] >= 2)
            continue;
        const double d = r[j] * sigma / sqrt(w[j]) - *mean;
        dev2 += d * d;
    }
    *rms = sqrt(dev2 / n);
    *same_sign = fabs(signs / n);
    return n;
}

/* Forgetting weights exp(min(t − now, 0)/τ) and the rows' weights √w/σ, into w_out, sw_out;
 * returns Σ w. */
static PyObject *py_weights(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *o_t, *o_w, *o_sw;
    double now, tau, sigma;
    if (!PyArg_ParseTuple(args, "OdddOO:weights", &o_t, &now, &tau, &sigma, &o_w, &o_sw))
        return NULL;
    Buf b[3];
    memset(b, 0, sizeof b);
    PyObject *result = NULL;
    if (get_array(o_t, &b[0], "times", -1, 0, 0) < 0)
        goto out;
    const Py_ssize_t m = b[0].view.len / 8;
    if (get_array(o_w, &b[1], "weights", m, 1, 0) < 0 || get_array(o_sw, &b[2], "sw", m, 1, 0) < 0)
        goto out;
    if (!(tau > 0) || !(sigma > 0)) {
        PyErr_SetString(PyExc_ValueError, "tau and sigma must be > 0");
        goto out;
    }
    result = PyFloat_FromDouble(weights_into(b[0].view.buf, m, now, tau, sigma, b[1].view.buf, b[2].view.buf));
out:
    release_all(b, 3);
    return result;
}

/* The newest residuals' bias, back in μ units (r·σ/√w) from index `first`: their mean, their
 * root-mean-square deviation from it, and |Σ sign| / n. */
static PyObject *py_residual_bias(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *o_r, *o_w;
    Py_ssize_t first;
    double sigma;
    if (!PyArg_ParseTuple(args, "OOnd:residual_bias", &o_r, &o_w, &first, &sigma))
        return NULL;
    Buf b[2];
    memset(b, 0, sizeof b);
    PyObject *result = NULL;
    if (get_array(o_r, &b[0], "r_data", -1, 0, 0) < 0)
        goto out;
    const Py_ssize_t m = b[0].view.len / 8;
    if (get_array(o_w, &b[1], "weights", m, 0, 0) < 0)
        goto out;
    if (first < 0 || first >= m) {
        PyErr_SetString(PyExc_ValueError, "first: outside the residuals");
        goto out;
    }
    double mean, rms, same_sign;
    residual_stats(b[0].view.buf, b[1].view.buf, NULL, first, m, sigma, &mean, &rms, &same_sign);
    result = Py_BuildValue("(ddd)", mean, rms, same_sign);
out:
    release_all(b, 2);
    return result;
}

/* The inverse of the normal matrix's block of free parameters, zero elsewhere, into `out`
 * (Gauss–Jordan with partial pivoting). False, and `out` untouched, if the block is singular. */
static PyObject *py_inverse_free(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *o_n, *o_free, *o_out;
    if (!PyArg_ParseTuple(args, "OOO:inverse_free", &o_n, &o_free, &o_out))
        return NULL;
    double free_f[MAX_POINTS];
    if (floats(o_free, free_f, "free") != NP) {
        if (!PyErr_Occurred())
            PyErr_Format(PyExc_ValueError, "free: %d flags", NP);
        return NULL;
    }
    Buf b[2];
    memset(b, 0, sizeof b);
    PyObject *result = NULL;
    if (get_array(o_n, &b[0], "normal", NP * NP, 0, 0) < 0 || get_array(o_out, &b[1], "out", NP * NP, 1, 0) < 0)
        goto out;
    const double *N = b[0].view.buf;
    int idx[NP], k = 0;
    for (int i = 0; i < NP; i++)
        if (free_f[i] != 0.0)
            idx[k++] = i;
    double A[NP][2 * NP];
    for (int i = 0; i < k; i++)
        for (int j = 0; j < k; j++) {
            A[i][j] = N[idx[i] * NP + idx[j]];
            A[i][k + j] = i == j;
        }
    int singular = 0;
    for (int c = 0; c < k && !singular; c++) {
        int piv = c;
        for (int r = c + 1; r < k; r++)
            if (fabs(A[r][c]) > fabs(A[piv][c]))
                piv = r;
        if (A[piv][c] == 0.0 || !isfinite(A[piv][c])) {
            singular = 1;
            break;
        }
        if (piv != c)
            for (int j = 0; j < 2 * k; j++) {
                const double t = A[c][j];
                A[c][j] = A[piv][j];
                A[piv][j] = t;
            }
        const double inv = 1.0 / A[c][c];
        for (int j = 0; j < 2 * k; j++)
            A[c][j] *= inv;
        for (int r = 0; r < k; r++)
            if (r != c && A[r][c] != 0.0) {
                const double f = A[r][c];
                for (int j = 0; j < 2 * k; j++)
                    A[r][j] -= f * A[c][j];
            }
    }
    if (!singular) {
        double *o = b[1].view.buf;
        memset(o, 0, NP * NP * sizeof(double));
        for (int i = 0; i < k; i++)
            for (int j = 0; j < k; j++)
                o[idx[i] * NP + idx[j]] = A[i][k + j];
    }
    result = singular ? Py_False : Py_True;
    Py_INCREF(result);
out:
    release_all(b, 2);
    return result;
}

/* _Window.append for several samples of one instant, at index k of the window's columns. */
static PyObject *py_append_samples(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    PyObject *slip_o, *speed_o, *mu_o, *time_o, *wheel_o, *lam_v_o, *pow_o, *stiff_o, *slips_o, *mus_o, *wheels_o;
    Py_ssize_t k;
    double speed, time_s, alpha, patch_length, max_slip;
    /* (METH_FASTCALL: converted here, once per update with samples, without a format string) */
    if (!arg_count("append_samples", nargs, 10))
        return NULL;
    if (!PyTuple_Check(args[0]) || PyTuple_GET_SIZE(args[0]) != 8) {
        PyErr_SetString(PyExc_TypeError, "append_samples: columns must be a tuple of 8 arrays");
        return NULL;
    }
    slip_o = PyTuple_GET_ITEM(args[0], 0), speed_o = PyTuple_GET_ITEM(args[0], 1), mu_o = PyTuple_GET_ITEM(args[0], 2);
    time_o = PyTuple_GET_ITEM(args[0], 3), wheel_o = PyTuple_GET_ITEM(args[0], 4);
    lam_v_o = PyTuple_GET_ITEM(args[0], 5), pow_o = PyTuple_GET_ITEM(args[0], 6), stiff_o = PyTuple_GET_ITEM(args[0], 7);
    slips_o = args[2], mus_o = args[4], wheels_o = args[6];
    if (!arg_ssize(args[1], &k) || !arg_double(args[3], &speed) || !arg_double(args[5], &time_s)
        || !arg_double(args[7], &alpha) || !arg_double(args[8], &patch_length) || !arg_double(args[9], &max_slip))
        return NULL;
    double slips[MAX_POINTS], mus[MAX_POINTS], wheels[MAX_POINTS];
    const Py_ssize_t n = floats(slips_o, slips, "slips");
    if (n < 0 || floats(mus_o, mus, "mus") != n || floats(wheels_o, wheels, "wheels") != n) {
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_ValueError, "append_samples: slips, mus and wheels differ in length");
        return NULL;
    }
    Buf b[8] = {{0}};
    PyObject *objs[8] = {slip_o, speed_o, mu_o, time_o, wheel_o, lam_v_o, pow_o, stiff_o};
    for (int j = 0; j < 8; j++) {
        if (get_array(objs[j], &b[j], "columns", -1, 1, j == 4) < 0) {
            release_all(b, 8);
            return NULL;
        }
        if (k < 0 || k + n > b[j].view.len / b[j].view.itemsize) {
            release_all(b, 8);
            PyErr_SetString(PyExc_IndexError, "append_samples: past the end of the window's columns");
            return NULL;
        }
    }
    double *slip_a = b[0].view.buf, *speed_a = b[1].view.buf, *mu_a = b[2].view.buf, *time_a = b[3].view.buf;
    Py_ssize_t *wheel_a = b[4].view.buf;
    double *lam_v_a = b[5].view.buf, *pow_a = b[6].view.buf, *stiff_a = b[7].view.buf;
    for (Py_ssize_t i = 0; i < n; i++) {
        const Py_ssize_t at = k + i;
        const double lam = max_slip < slips[i] ? max_slip : slips[i];   /* min(slip, MAX_MODEL_SLIP) */
        const double lam_v = lam * speed;
        slip_a[at] = slips[i];
        speed_a[at] = speed;
        mu_a[at] = mus[i];
        time_a[at] = time_s;
        wheel_a[at] = (Py_ssize_t)wheels[i];
        lam_v_a[at] = lam_v;
        pow_a[at] = lam_v > 0 ? pow(lam_v, alpha) : 0.0;
        stiff_a[at] = patch_length * lam / (1.0 - lam);
    }
    release_all(b, 8);
    Py_RETURN_NONE;
}

/* fit_window(arrays, lo, hi, now, tau, sigma, jump_t, x, lb, ub, prior, inv_prior_std, tie, gradient,
 *            normal, constants, radius, max_iterations, ftol, xtol, gtol, predicted_ftol, max_rejections,
 *            rows_x, cached_n) -> (w_sum, radius, r·r, first, mean, rms, same_sign, n_front, front_mean,
 *                                   front_rms, front_same_sign)
 *
 * One update's fit on the window's own columns [lo, hi), without slicing them in Python:
 * `weights` (into scratch rows 2 and 3), `solve` (residuals into scratch rows 0 and 1, the row
 * cache in core_rows[lo:hi], valid for its first cached_n samples at rows_x), then the data
 * residuals' sum of squares and `residual_bias` of the samples from `search_left(jump_t)` on
 * (`first` relative to lo; mean, rms and same_sign 0 when there are none), then the same of the
 * front wheels' among them and how many those are.
 * arrays: (pow_lam_v, stiff, lam_v, mu, wheel, time, scratch (4 x capacity), core_rows (capacity x 5)). */
/* METH_FASTCALL, its 25 arguments converted here (PyArg_ParseTuple's format was a tenth of the call). */
static PyObject *py_fit_window(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    PyObject *arrays, *objs[9];
    Py_ssize_t lo, hi, cached_n;
    double now, tau, sigma, jump_t, constants[6], radius, ftol, xtol, gtol, predicted_ftol;
    int max_iterations, max_rejections;
    if (!arg_count("fit_window", nargs, 25))
        return NULL;
    arrays = args[0];
    if (!PyTuple_Check(arrays) || !PyTuple_Check(args[15]) || PyTuple_GET_SIZE(args[15]) != 6) {
        PyErr_SetString(PyExc_TypeError, "fit_window: arrays must be a tuple, constants a 6-tuple");
        return NULL;
    }
    for (int i = 0; i < 8; i++)
        objs[i] = args[7 + i];
    objs[8] = args[23];
    for (int i = 0; i < 6; i++)
        if (!arg_double(PyTuple_GET_ITEM(args[15], i), &constants[i]))
            return NULL;
    if (!arg_ssize(args[1], &lo) || !arg_ssize(args[2], &hi) || !arg_double(args[3], &now)
        || !arg_double(args[4], &tau) || !arg_double(args[5], &sigma) || !arg_double(args[6], &jump_t)
        || !arg_double(args[16], &radius) || !arg_int(args[17], &max_iterations) || !arg_double(args[18], &ftol)
        || !arg_double(args[19], &xtol) || !arg_double(args[20], &gtol) || !arg_double(args[21], &predicted_ftol)
        || !arg_int(args[22], &max_rejections) || !arg_ssize(args[24], &cached_n))
        return NULL;
    const double mu_c = constants[0], dmu = constants[1], alpha = constants[2], sc4 = constants[3],
                 sc5 = constants[4], sc6 = constants[5];
    if (PyTuple_GET_SIZE(arrays) != 8) {
        PyErr_SetString(PyExc_ValueError, "fit_window: arrays are the window's 8 columns");
        return NULL;
    }
    static const char *col_names[8] = {"pow_lam_v", "stiff", "lam_v", "mu", "wheel", "time", "scratch", "core_rows"};
    static const char *par_names[9] = {"x", "lb", "ub", "prior", "inv_prior_std", "tie", "gradient", "normal",
                                       "rows_x"};
    static const Py_ssize_t par_counts[9] = {NP, NP, NP, NP, NP, NT * NW, NP, NP * NP, NP};
    Buf b[17];
    memset(b, 0, sizeof b);
    PyObject *result = NULL;
    double *rows_trial = NULL;
    if (get_array(PyTuple_GET_ITEM(arrays, 5), &b[5], "time", -1, 0, 0) < 0)
        goto out;
    const Py_ssize_t cap = b[5].view.len / 8;
    for (int i = 0; i < 8; i++) {
        if (i == 5)
            continue;
        const Py_ssize_t count = i == 6 ? 4 * cap : i == 7 ? ROW * cap : cap;
        if (get_array(PyTuple_GET_ITEM(arrays, i), &b[i], col_names[i], count, i >= 6, i == 4) < 0)
            goto out;
    }
    for (int i = 0; i < 9; i++)
        if (get_array(objs[i], &b[8 + i], par_names[i], par_counts[i], i == 0 || i == 6 || i == 7, 0) < 0)
            goto out;
    if (lo < 0 || hi <= lo || hi > cap || cached_n < 0 || cached_n > hi - lo) {
        PyErr_SetString(PyExc_ValueError, "fit_window: lo, hi or cached_n outside the window");
        goto out;
    }
    if (!(tau > 0) || !(sigma > 0) || max_iterations < 0 || max_rejections < 1 || sc4 == 0 || sc5 == 0) {
        PyErr_SetString(PyExc_ValueError, "fit_window: bad settings");
        goto out;
    }
    const Py_ssize_t m = hi - lo;
    const Py_ssize_t *wheel = (const Py_ssize_t *)b[4].view.buf + lo;
    for (Py_ssize_t j = 0; j < m; j++)
        if (wheel[j] < 0 || wheel[j] >= NW) {
            PyErr_SetString(PyExc_ValueError, "wheel: index outside 0..3");
            goto out;
        }
    if (!(rows_trial = PyMem_Malloc((size_t)(ROW * m + 1) * sizeof(double)))) {
        PyErr_NoMemory();
        goto out;
    }
    double *scratch = b[6].view.buf;
    double *r_data = scratch + lo, *r_work = scratch + cap + lo, *w = scratch + 2 * cap + lo, *sw = scratch + 3 * cap + lo;
    const double *t = (const double *)b[5].view.buf + lo;
    const double w_sum = weights_into(t, m, now, tau, sigma, w, sw);
    Problem p = {m, (const double *)b[0].view.buf + lo, (const double *)b[1].view.buf + lo,
                 (const double *)b[2].view.buf + lo, (const double *)b[3].view.buf + lo, sw, wheel,
                 b[11].view.buf, b[12].view.buf, b[13].view.buf, mu_c, dmu, alpha, sc4, sc5, sc6};
    const Outcome o = solve(&p, b[8].view.buf, b[9].view.buf, b[10].view.buf, radius, max_iterations, ftol, xtol,
                            gtol, max_rejections, predicted_ftol, b[14].view.buf, b[15].view.buf, r_data, r_work,
                            (double *)b[7].view.buf + ROW * lo, b[16].view.buf, cached_n, rows_trial);
    const double rr = dot_of(r_data, r_data, m);
    const Py_ssize_t first = search_left(t, 0, m, jump_t);
    double mean = 0.0, rms = 0.0, same_sign = 0.0, f_mean = 0.0, f_rms = 0.0, f_same_sign = 0.0;
    Py_ssize_t n_front = 0;
    if (first < m) {
        residual_stats(r_data, w, NULL, first, m, sigma, &mean, &rms, &same_sign);
        n_front = residual_stats(r_data, w, wheel, first, m, sigma, &f_mean, &f_rms, &f_same_sign);
    }
    result = Py_BuildValue("(dddndddnddd)", w_sum, o.radius, rr, first, mean, rms, same_sign, n_front, f_mean, f_rms,
                           f_same_sign);
out:
    PyMem_Free(rows_trial);
    release_all(b, 17);
    return result;
}

/* drift_reference(history, since, span) -> float | None: LugreTrustRegionEstimator._confidence's
 * reference, the median of the μ_max of the (time, μ_max) pairs of `history` (ascending times)
 * from the first at or after `since` to `span` after it. None when some of those values are NaN
 * (Python's sort puts them where its comparisons happen to; the caller's loop decides then). */
static PyObject *py_drift_reference(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *history;
    double since, span;
    if (!PyArg_ParseTuple(args, "Odd:drift_reference", &history, &since, &span))
        return NULL;
    const Py_ssize_t size = PyObject_Length(history);
    if (size < 0)
        return NULL;
    double *values = PyMem_Malloc((size_t)(size + 1) * sizeof(double));
    if (!values)
        return PyErr_NoMemory();
    PyObject *it = PyObject_GetIter(history), *item, *result = NULL;
    if (!it)
        goto out;
    Py_ssize_t n = 0;
    double until = INFINITY;
    int has_nan = 0;
    while ((item = PyIter_Next(it))) {
        double t = 0.0, m = 0.0;
        const int ok = PyTuple_Check(item) && PyTuple_GET_SIZE(item) == 2;
        if (ok) {
            t = PyFloat_AsDouble(PyTuple_GET_ITEM(item, 0));
            m = PyFloat_AsDouble(PyTuple_GET_ITEM(item, 1));
        }
        Py_DECREF(item);
        if (!ok) {
            PyErr_SetString(PyExc_TypeError, "drift_reference: history holds (time, mu_max) pairs");
            goto out;
        }
        if (PyErr_Occurred())
            goto out;
        if (t < since)
            continue;
        if (n == 0)
            until = t + span;
        else if (t > until)
            break;
        if (n >= size) {   /* (the deque grew while iterated: not from this single-threaded caller) */
            PyErr_SetString(PyExc_RuntimeError, "drift_reference: history changed size");
            goto out;
        }
        has_nan |= m != m;
        values[n++] = m;
    }
    if (PyErr_Occurred())
        goto out;
    if (n == 0) {
        PyErr_SetString(PyExc_ValueError, "drift_reference: no value at or after since");
        goto out;
    }
    if (has_nan) {
        result = Py_NewRef(Py_None);
        goto out;
    }
    sort_values(values, n);
    result = PyFloat_FromDouble(values[n / 2]);
out:
    Py_XDECREF(it);
    PyMem_Free(values);
    return result;
}

/* estimator._top_elasticity: one wheel's least-squares slope of μ on slip over its samples of
 * [search_left(times, since), end) whose slip lies between their median and 95 % quantile, as
 * (dμ/dλ)·mean λ / mean μ, with that number's standard error from the fit's residuals, and the
 * smear: the rms of those samples' slip sweeps within the derivative filter (`spread`, 4 rows of
 * cap: the window ends' slips and weights) over the standard deviation of their slips (∞ for
 * a sweep over slips that do not spread at all); None with fewer than min_n samples or
 * min_upper of them in that band. */
static PyObject *py_top_elasticity(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *o_slip, *o_mu, *o_wheel, *o_times, *o_spread;
    Py_ssize_t start, end, min_n, min_upper;
    double since;
    int wheel_i;
    if (!PyArg_ParseTuple(args, "OOOOOnndinn:top_elasticity", &o_slip, &o_mu, &o_wheel, &o_times, &o_spread, &start,
                          &end, &since, &wheel_i, &min_n, &min_upper))
        return NULL;
    Buf b[5];
    memset(b, 0, sizeof b);
    PyObject *result = NULL;
    double *sorted = NULL;
    const Py_ssize_t cap = get_slip_mu_wheel(o_slip, o_mu, o_wheel, b);
    if (cap < 0 || get_array(o_times, &b[3], "times", cap, 0, 0) < 0
        || get_array(o_spread, &b[4], "spread", 4 * cap, 0, 0) < 0)
        goto out;
    if (start < 0 || end < start || end > cap) {
        PyErr_SetString(PyExc_ValueError, "top_elasticity: start, end outside the window");
        goto out;
    }
    const double *slip = b[0].view.buf, *mu = b[1].view.buf, *times = b[3].view.buf, *spread = b[4].view.buf;
    const double *s_lo = spread, *s_hi = spread + cap, *a_lo = spread + 2 * cap, *a_hi = spread + 3 * cap;
    const Py_ssize_t *wheel = b[2].view.buf;
    const Py_ssize_t lo = search_left(times, start, end, since);
    sorted = PyMem_Malloc(sizeof(double) * (size_t)(end - lo + 1));
    if (!sorted) {
        PyErr_NoMemory();
        goto out;
    }
    Py_ssize_t n = 0;
    for (Py_ssize_t j = lo; j < end; j++)
        if (wheel[j] == wheel_i)
            sorted[n++] = slip[j];
    if (n < min_n || n < 1) {
        result = Py_NewRef(Py_None);
        goto out;
    }
    sort_values(sorted, n);
    const double median = quantile_sorted(sorted, n, 0.5), top = quantile_sorted(sorted, n, 0.95);
    Py_ssize_t m = 0;
    double sl = 0.0, su = 0.0;
    for (Py_ssize_t j = lo; j < end; j++)
        if (wheel[j] == wheel_i && slip[j] >= median && slip[j] <= top) {
            sl += slip[j];
            su += mu[j];
            m++;
        }
    if (m < min_upper || !(top - median >= 1e-4)) {
        result = Py_NewRef(Py_None);
        goto out;
    }
    const double l_mean = sl / m, u_mean = su / m;
    double sxy = 0.0, sxx = 0.0;
    for (Py_ssize_t j = lo; j < end; j++)
        if (wheel[j] == wheel_i && slip[j] >= median && slip[j] <= top) {
            const double dl = slip[j] - l_mean;
            sxy += dl * (mu[j] - u_mean);
            sxx += dl * dl;
        }
    const double sxx_ = sxx > 1e-12 ? sxx : 1e-12;
    const double slope = sxy / sxx_;
    double rss = 0.0, sweep = 0.0;
    for (Py_ssize_t j = lo; j < end; j++)
        if (wheel[j] == wheel_i && slip[j] >= median && slip[j] <= top) {
            const double r = (mu[j] - u_mean) - slope * (slip[j] - l_mean);
            rss += r * r;
            const double d_lo = s_lo[j] - slip[j], d_hi = s_hi[j] - slip[j];
            sweep += a_lo[j] * d_lo * d_lo + a_hi[j] * d_hi * d_hi;
        }
    const double scale = l_mean / (u_mean > 1e-6 ? u_mean : 1e-6);
    const double slope_se = sqrt(rss / (double)(m > 2 ? m - 2 : 1) / sxx_);
    const double smear = sxx > 0.0 ? sqrt(sweep / sxx) : (sweep > 0.0 ? INFINITY : 0.0);
    result = Py_BuildValue("(ddd)", slope * scale, slope_se * scale, smear);
out:
    PyMem_Free(sorted);
    release_all(b, 5);
    return result;
}

/* search_left(times, lo, hi, t) -> int: numpy's `times[lo:hi].searchsorted(t, side="left") + lo`
 * (the first k with times[k] >= t; NaN sorts last), on a float64 array without the slice. */
static PyObject *py_search_left(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *o_times;
    Py_ssize_t lo, hi;
    double t;
    if (!PyArg_ParseTuple(args, "Onnd:search_left", &o_times, &lo, &hi, &t))
        return NULL;
    Buf b[1];
    memset(b, 0, sizeof b);
    if (get_array(o_times, &b[0], "times", -1, 0, 0) < 0) {
        release_all(b, 1);
        return NULL;
    }
    if (lo < 0 || hi < lo || hi > b[0].view.len / 8) {
        release_all(b, 1);
        PyErr_SetString(PyExc_ValueError, "search_left: lo, hi outside the array");
        return NULL;
    }
    const Py_ssize_t k = search_left(b[0].view.buf, lo, hi, t);
    release_all(b, 1);
    return PyLong_FromSsize_t(k);
}

static PyMethodDef methods[] = {
    {"append_samples", (PyCFunction)(void (*)(void))py_append_samples, METH_FASTCALL,
     "append_samples(columns, k, slips, speed, mus, time_s, wheels, alpha, patch_length, max_slip) -> None\n\n"
     "_Window.append of one instant's samples (one per wheel) at index k of the window's 8 columns\n"
     "(slip, speed, mu, time, wheel, lam_v, pow_lam_v, stiff)."},
    {"solve", py_solve, METH_VARARGS,
     "solve(pow_lam_v, stiff, lam_v, mu, wheel, sw, x, lb, ub, prior, inv_prior_std, tie, gradient, normal,\n"
     "      r_data, r_work, (mu_c, dmu, alpha, sc4, sc5, sc6), radius, max_iterations, ftol, xtol, gtol,\n"
     "      predicted_ftol, max_rejections[, (rows, rows_x, cached_n)]) -> (cost, radius, iterations, converged,\n"
     "      evaluations)\n\n"
     "The estimator's fit: x (in/out), gradient, normal and r_data (the weighted data residuals)\n"
     "are written in place at the returned point."},
    {"peaks_near", py_peaks_near, METH_VARARGS,
     "peaks_near(v, thetas, near, params) -> (mus, lams) | None\n\n"
     "tyre_model._peaks_near for up to 16 wheels."},
    {"peaks_grid", py_peaks_grid, METH_VARARGS,
     "peaks_grid(v, thetas, grid, fine, params) -> (mus, lams)\n\n"
     "tyre_model.peaks without `near` (the grid search) for up to 16 values of theta."},
    {"mu_partials_few", py_mu_partials_few, METH_VARARGS,
     "mu_partials_few(lams, v, thetas, params) -> (mus, rows)\n\n"
     "tyre_model.braking_mu_and_partials_few; rows flat, 4 per point."},
    {"wheel_stats", py_wheel_stats, METH_VARARGS,
     "wheel_stats(slip, mu, wheel, times, lag, elasticity) -> 4 tuples of 12 floats\n\n"
     "estimator._wheel_stats_numpy: n, q10, q90, lam_lo, lam_hi, mu_hi, run-away rate, s2, s3, s4, y1, y2."},
    {"excess_over_fit", py_excess_over_fit, METH_VARARGS,
     "excess_over_fit(scratch, slip, wheel, lo, hi, wheel_mu, fitted_mu, peak_slip, edges, min_n) -> float\n\n"
     "EstimateConfidence._excess_over_fit's band means over the window's samples [lo, hi)."},
    {"band_ratio", py_band_ratio, METH_VARARGS,
     "band_ratio(slip, mu, wheel, lo, hi, peak_mu, peak_slip, edges, min_n) -> float\n\n"
     "EstimateConfidence._band_ratio_of's band means over the window's samples [lo, hi)."},
    {"data_peaks", py_data_peaks, METH_VARARGS,
     "data_peaks(slip, mu, wheel, lo, hi, k, min_n, margin) -> [4 floats]\n\n"
     "estimator._data_peaks's group statistics over the window's samples [lo, hi)."},
    {"recent_wheel_stats", py_recent_wheel_stats, METH_VARARGS,
     "recent_wheel_stats(slip, columns, lo, hi, threshold, lag, elasticity) -> wheel_stats of the window's\n"
     "samples whose forgetting weight (scratch row 2, from fit_window) exceeds threshold"},
    {"peak_report", (PyCFunction)(void (*)(void))py_peak_report, METH_FASTCALL,
     "peak_report(wheel_mu, wheel_lam, support, slip_floor, peak_extrapolation, extrapolation_max_slip, thetas,\n"
     "            v, params, (sc4, sc5, sc6), cov_unit,\n"
     "            variance_factor, share) -> (wheel_mu, wheel_lam, capped, mu_max, slip_star, mu_std, wheel_std)"},
    {"weights", py_weights, METH_VARARGS,
     "weights(times, now, tau, sigma, weights_out, sw_out) -> sum of the weights exp(min(t - now, 0)/tau);\n"
     "sw_out gets sqrt(w)/sigma"},
    {"residual_bias", py_residual_bias, METH_VARARGS,
     "residual_bias(r_data, weights, first, sigma) -> (mean, rms deviation, |sum of signs| / n) of r*sigma/sqrt(w)"},
    {"inverse_free", py_inverse_free, METH_VARARGS,
     "inverse_free(normal, free, out) -> bool: the inverse of the free parameters' block, zero elsewhere"},
    {"fit_window", (PyCFunction)(void (*)(void))py_fit_window, METH_FASTCALL,
     "fit_window(arrays, lo, hi, now, tau, sigma, jump_t, x, lb, ub, prior, inv_prior_std, tie, gradient, normal,\n"
     "constants, radius, max_iterations, ftol, xtol, gtol, predicted_ftol, max_rejections, rows_x, cached_n)\n"
     "-> (w_sum, radius, r.r, first, mean, rms, same_sign, n_front, front_mean, front_rms, front_same_sign): weights,\n"
     "solve and residual_bias (all samples, the front wheels' alone) on the window's columns"},
    {"drift_reference", py_drift_reference, METH_VARARGS,
     "drift_reference(history, since, span) -> float | None: the median mu_max of the (time, mu_max) pairs\n"
     "from the first at or after since to span after it; None when one of them is NaN"},
    {"top_elasticity", py_top_elasticity, METH_VARARGS,
     "top_elasticity(slip, mu, wheel, times, spread, start, end, since, wheel_i, min_n, min_upper)"
     " -> (float, float, float) | None\n\n"
     "estimator._top_elasticity: one wheel's local elasticity over the top half of its recent slips, its\n"
     "standard error and the smear of those slips by the derivative filter's sweeps."},
    {"spread_loss", py_spread_loss, METH_VARARGS,
     "spread_loss(slip, speed, mu, wheel, spread, lo, hi, thetas, params) -> float\n\n"
     "estimator._spread_loss_numpy: the mean share of the fitted mu the filter's spread of slips loses,\n"
     "over the window's samples [lo, hi) at the top of their wheel's data."},
    {"search_left", py_search_left, METH_VARARGS,
     "search_left(times, lo, hi, t) -> int: times[lo:hi].searchsorted(t, side='left') + lo"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_fitcore",
                                    "The estimator's per-update numerics (fit, peaks, partials), compiled.", -1, methods};

PyMODINIT_FUNC PyInit__fitcore(void)
{
    return PyModule_Create(&module);
}
