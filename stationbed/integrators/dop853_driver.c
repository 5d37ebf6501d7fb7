/* stationbed: DOP853 segment driver, compiled together with the casadi-generated
 * `dop853_step` and `dop853_dense` functions (stationbed/integrators/dop853.py builds them).
 *
 * It is the same algorithm as DOP853._window_python (Hairer's step-size control as in
 * scipy's DOP853, dense output for requested times inside a step, exact landing on the
 * segment end), moved to C so that one call advances many steps without a Python round trip
 * per step. Keep the two in step: a test runs both and compares.
 *
 * sb_dop853_window advances a smooth segment, ending at t_end, one window of requested times at
 * a time: it fills `out` with the states at the nw increasing times `ts` (after the previous
 * window's, the segment's last window ending with t_end) and returns as soon as the window is
 * full, keeping what the next window needs: st = [t, t_prev, h_prev], x and k1 (state and
 * derivative at t), xp and F (start state and dense-output coefficients of the last accepted
 * step, for requested times it spanned past the window), *h_io (the step-size memory). A
 * window never forces a step to end: cutting the times into windows leaves the steps, and so
 * every number, as one window holding them all.
 *
 * Returns 0 on success, 1 on step-size underflow, 2 on a non-finite state; `info` gets
 * [n_rhs, n_steps, n_rejected] added and info[3] = the rows of the window filled; st[0] is the
 * time reached.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* the 7th-order dense output at fraction th of a step from x0 with coefficients F (7 x nx) */
static void sb_dop853_interp(int nx, double th, const double* x0, const double* F, const double* P, double* y_out) {
  double pw[8];
  int m, j, k;
  pw[0] = 1.0;
  for (m = 1; m < 8; ++m) pw[m] = pw[m - 1] * th;
  for (k = 0; k < nx; ++k) {
    double y = x0[k];
    for (m = 0; m < 8; ++m) {
      double c = 0.0;
      for (j = 0; j < 7; ++j) c += P[m * 7 + j] * F[j * nx + k];
      y += pw[m] * c;
    }
    y_out[k] = y;
  }
}

CASADI_SYMBOL_EXPORT int sb_dop853_window(int nx, int nw, const double* ts, double t_end, double* st,
                                          double* x, double* k1, double* xp, double* F, const double* u,
                                          const double* p, const double* tol, double* h_io, double max_step,
                                          const double* P, double* out, long long* info) {
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
  double t = st[0], h = 0.0, err = 0.0;
  int i = 0, rejected = 0, status = 0, k;
  /* requested times inside the last accepted step (it ended past the previous window) */
  while (i < nw && ts[i] < t) {
    sb_dop853_interp(nx, (ts[i] - st[1]) / st[2], xp, F, P, out + (size_t)i * nx);
    ++i;
  }
  if (i < nw && ts[i] == t) { memcpy(out + (size_t)i * nx, x, sizeof(double) * (size_t)nx); ++i; }
  while (i < nw && t < t_end) {
    double remaining = t_end - t;
    int clipped;
    h = fmin(*h_io, max_step);
    clipped = h >= remaining * (1.0 - 1e-12);
    if (clipped) h = remaining;
    else if (h > 0.5 * remaining) h = 0.5 * remaining;
    if (h <= 1e-12 * fmax(1.0, fabs(t))) { status = 1; break; }
    int dense = ts[i] < t_end && ts[i] < t + h;
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
        memcpy(xp, x, sizeof(double) * (size_t)nx);
        st[1] = t;
        st[2] = h;
        while (i < nw && ts[i] < t_new) {
          sb_dop853_interp(nx, (ts[i] - t) / h, x, F, P, out + (size_t)i * nx);
          ++i;
        }
      }
      t = t_new;
      memcpy(x, x_new, sizeof(double) * (size_t)nx);
      memcpy(k1, k_new, sizeof(double) * (size_t)nx);
      if (i < nw && ts[i] == t) { memcpy(out + (size_t)i * nx, x, sizeof(double) * (size_t)nx); ++i; }
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
  /* at the segment end: its state (a time within rounding of it, never stepped to, gets it too) */
  if (status == 0 && t >= t_end) {
    for (; i < nw; ++i) memcpy(out + (size_t)i * nx, x, sizeof(double) * (size_t)nx);
  }
  info[3] = i;
  st[0] = t;
  free(arg); free(res); free(iw); free(w); free(x_new); free(k_new);
  return status;
}
