/* stationbed: DOP853 segment driver, compiled together with the casadi-generated
 * `dop853_step` and `dop853_dense` functions (stationbed/integrators.py builds them).
 *
 * It is the same algorithm as DOP853._integrate_python (Hairer's step-size control as in
 * scipy's DOP853, dense output for requested times inside a step, exact landing on the
 * segment end), moved to C so that one call advances a whole smooth segment without a
 * Python round trip per step. Keep the two in step: a test runs both and compares.
 *
 * Returns 0 on success, 1 on step-size underflow, 2 on a non-finite state; `info` gets
 * [n_rhs, n_steps, n_rejected, rows_filled] and *t_stop the time reached.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

CASADI_SYMBOL_EXPORT int sb_dop853_segment(int nx, int nts, const double* ts, double* x, double* k1,
                                           const double* u, const double* p, const double* tol,
                                           double* h_io, double max_step, const double* P,
                                           double* out, long long* info, double* t_stop) {
  casadi_int sa, sr, si, sw, sa2, sr2, si2, sw2;
  dop853_step_work(&sa, &sr, &si, &sw);
  dop853_dense_work(&sa2, &sr2, &si2, &sw2);
  if (sa2 > sa) sa = sa2;
  if (sr2 > sr) sr = sr2;
  if (si2 > si) si = si2;
  if (sw2 > sw) sw = sw2;
  const casadi_real** arg = (const casadi_real**)calloc((size_t)sa + 1, sizeof(casadi_real*));
  casadi_real** res = (casadi_real**)calloc((size_t)sr + 1, sizeof(casadi_real*));
  casadi_int* iw = (casadi_int*)calloc((size_t)si + 1, sizeof(casadi_int));
  casadi_real* w = (casadi_real*)calloc((size_t)sw + 1, sizeof(casadi_real));
  double* x_new = (double*)calloc((size_t)nx, sizeof(double));
  double* k_new = (double*)calloc((size_t)nx, sizeof(double));
  double* F = (double*)calloc((size_t)(7 * nx), sizeof(double));
  double t = ts[0], t_end = ts[nts - 1], h = 0.0, err = 0.0;
  int i = 1, rejected = 0, status = 0, k;
  memcpy(out, x, sizeof(double) * (size_t)nx);
  while (t < t_end) {
    double remaining = t_end - t;
    int clipped;
    h = fmin(*h_io, max_step);
    clipped = h >= remaining * (1.0 - 1e-12);
    if (clipped) h = remaining;
    else if (h > 0.5 * remaining) h = 0.5 * remaining;
    if (h <= 1e-12 * fmax(1.0, fabs(t))) { status = 1; break; }
    int dense = (i < nts - 1) && ts[i] < t + h;
    /* set at every call: a generated function may use arg[] and res[] past its own inputs and
       outputs as scratch (a call to another generated function, such as the RHS) */
    arg[0] = &t; arg[1] = x; arg[2] = k1; arg[3] = &h; arg[4] = u; arg[5] = p; arg[6] = tol;
    res[0] = x_new; res[1] = k_new; res[2] = &err; res[3] = F;
    if (dense) dop853_dense(arg, res, iw, w, 0);
    else dop853_step(arg, res, iw, w, 0);
    info[0] += 12 + (dense ? 3 : 0);
    if (!isfinite(err)) {
      for (k = 0; k < nx; ++k) if (!isfinite(x[k])) { status = 2; break; }
      if (status) break;
      err = INFINITY;
    }
    if (err <= 1.0) {
      double t_new = clipped ? t_end : t + h, factor;
      if (dense) {
        while (i < nts - 1 && ts[i] < t_new) {
          double th = (ts[i] - t) / h, pw[8];
          int m, j;
          pw[0] = 1.0;
          for (m = 1; m < 8; ++m) pw[m] = pw[m - 1] * th;
          for (k = 0; k < nx; ++k) {
            double y = x[k];
            for (m = 0; m < 8; ++m) {
              double c = 0.0;
              for (j = 0; j < 7; ++j) c += P[m * 7 + j] * F[j * nx + k];
              y += pw[m] * c;
            }
            out[(size_t)i * nx + k] = y;
          }
          ++i;
        }
      }
      t = t_new;
      memcpy(x, x_new, sizeof(double) * (size_t)nx);
      memcpy(k1, k_new, sizeof(double) * (size_t)nx);
      if (i < nts && ts[i] == t) { memcpy(out + (size_t)i * nx, x, sizeof(double) * (size_t)nx); ++i; }
      info[1] += 1;
      factor = (err == 0.0) ? 10.0 : fmin(10.0, 0.9 * pow(err, -1.0 / 8.0));
      if (rejected) factor = fmin(1.0, factor);
      *h_io = clipped ? fmax(*h_io, h * factor) : h * factor;
      rejected = 0;
    } else {
      info[2] += 1;
      *h_io = h * fmax(0.2, 0.9 * pow(err, -1.0 / 8.0));
      rejected = 1;
    }
  }
  if (status == 0) { memcpy(out + (size_t)(nts - 1) * nx, x, sizeof(double) * (size_t)nx); i = nts; }
  info[3] = i;
  *t_stop = t;
  free(arg); free(res); free(iw); free(w); free(x_new); free(k_new); free(F);
  return status;
}
