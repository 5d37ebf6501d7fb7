/* The pd law served over a socket (stationbed's socket-law protocol, docs/socket_law.md), in C.
 *
 * One file, C99 and POSIX sockets, no library:  cc -O2 -ffp-contract=off -o pd_client pd_client.c -lm
 * (-ffp-contract=off: no fused multiply-add, so every operation rounds as Python's do and a run
 * flown through it is bit-identical to the in-process pd of controllers/pd.py.)
 *
 *     ./pd_client 5555          # listens on 127.0.0.1:5555 (0: a free port)
 *
 * The first line on stdout is "listening on 127.0.0.1:PORT". Each connection is one run,
 * served by a child process (fork), so runs may overlap (a Monte Carlo's samples).
 * The law binds the measurement's fields by name from HELLO; the frame is little-endian, and
 * this file assumes a little-endian machine (x86-64, arm64).
 */
#include <arpa/inet.h>
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

enum { VERSION = 1, HELLO = 1, READY = 2, MEAS = 3, CMD = 4, END = 5, ERROR = 6 };
#define HEADER 24 /* u32 size (bytes after it), u16 version, u16 kind, i64 tick, f64 t */
#define MAXY 512
/* how long a frame is awaited by polling the socket before sleeping in read [ns]: a process woken
   from a blocking read on an idle core takes ~50 us to run again, and stationbed sends the next
   measurement ~10 us after it reads a command (at full speed) */
#ifndef SPIN_NS
#define SPIN_NS 100000L
#endif

static int read_all(int fd, void *buf, size_t n) {
    char *p = buf;
    while (n > 0) {
        ssize_t k = read(fd, p, n);
        if (k <= 0) return -1;
        p += k;
        n -= (size_t)k;
    }
    return 0;
}

static long now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1000000000L + ts.tv_nsec;
}

/* Spin or block while the next frame is awaited, whichever flew faster lately. A spin saves the
   wake-up of a process blocked on an idle core (on a virtual machine, a halted vCPU: ~25-50 us);
   on a loaded machine it costs instead (a process that never sleeps loses its turn to others'
   time slices). So: one epoch of EPOCH_TICKS frames timed each way, then EXPLOIT_EPOCHS epochs
   the faster way, and again; an epoch that misses more than SPINS_MISSED frames spinning blocks
   until the next cycle (stationbed does the same: docs/socket_law.md, "Speed"). */
#ifndef EPOCH_TICKS
#define EPOCH_TICKS 256
#endif
#define EXPLOIT_EPOCHS 8
#define SPINS_MISSED 8
static struct {
    int epoch, k, spin, missed; /* into the cycle (0 timed spinning, 1 blocking), frames into the epoch */
    long start, timed[2]; /* ns: when the epoch began; the last epoch timed blocking, spinning */
} W = {-1, EPOCH_TICKS, 0, 0, 0, {LONG_MAX, LONG_MAX}};

static int choose_spin(void) {
    if (W.k < EPOCH_TICKS) {
        W.k++;
        return W.spin;
    }
    long now = now_ns();
    if (W.epoch == 0) W.timed[1] = W.spin ? now - W.start : LONG_MAX; /* too many spins missed: not timed */
    if (W.epoch == 1) W.timed[0] = now - W.start;
    W.epoch = (W.epoch + 1) % (2 + EXPLOIT_EPOCHS);
    W.k = 1;
    W.missed = 0;
    W.start = now;
    W.spin = W.epoch < 2 ? W.epoch == 0 : W.timed[1] < W.timed[0];
    return W.spin;
}

/* a spin that ended before the frame came (stationbed shares this core, is paced, or was
   preempted): more than SPINS_MISSED in an epoch, and blocking until spinning is timed again */
static void missed(void) {
    if (++W.missed <= SPINS_MISSED) return;
    W.spin = 0;
    W.timed[1] = LONG_MAX;
}

/* read at least `least` bytes into buf, at most `most` (one frame); with spinning, the socket is
   polled (non-blocking recv) for SPIN_NS before a blocking one. The count read, -1 at the end. */
static long read_spin(int fd, void *buf, size_t least, size_t most, int spinning) {
    char *p = buf;
    size_t got = 0;
    long end = spinning ? now_ns() + SPIN_NS : 0;
    while (got < least) {
        ssize_t k = recv(fd, p + got, most - got, spinning ? MSG_DONTWAIT : 0);
        if (k < 0 && spinning && (errno == EAGAIN || errno == EWOULDBLOCK)) {
            if (now_ns() < end) continue;
            missed();
            spinning = 0;
            continue;
        }
        if (k <= 0) return -1;
        got += (size_t)k;
    }
    return (long)got;
}

static int write_all(int fd, const void *buf, size_t n) {
    const char *p = buf;
    while (n > 0) {
        ssize_t k = write(fd, p, n);
        if (k <= 0) return -1;
        p += k;
        n -= (size_t)k;
    }
    return 0;
}

static void header(char *buf, uint32_t size, uint16_t kind, int64_t tick, double t) {
    uint16_t version = VERSION;
    memcpy(buf, &size, 4);
    memcpy(buf + 4, &version, 2);
    memcpy(buf + 6, &kind, 2);
    memcpy(buf + 8, &tick, 8);
    memcpy(buf + 16, &t, 8);
}

static void send_text(int fd, uint16_t kind, const char *text) {
    size_t n = strlen(text);
    char *buf = malloc(HEADER + n);
    header(buf, (uint32_t)(HEADER - 4 + n), kind, -1, 0.0);
    memcpy(buf + HEADER, text, n);
    write_all(fd, buf, HEADER + n);
    free(buf);
}

/* the law: controllers/pd.py's _reset and _update, operation for operation */
typedef struct {
    double k, c, kc, lim, lim2, J[3][3], q_RO[4], w_RN_R[3];
    int lvlh, varying, gyro;
    int i_q, i_w, i_qon, i_won; /* where the fields are in the measurement */
} Pd;

static void qmul(const double *p, const double *q, double *r) {
    r[0] = p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3];
    r[1] = p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2];
    r[2] = p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1];
    r[3] = p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0];
}

static void rotate(const double *q, const double *v, double *r) {
    double w = q[0], x = q[1], y = q[2], z = q[3];
    double tx = 2.0 * (y * v[2] - z * v[1]);
    double ty = 2.0 * (z * v[0] - x * v[2]);
    double tz = 2.0 * (x * v[1] - y * v[0]);
    r[0] = v[0] - w * tx + (y * tz - z * ty);
    r[1] = v[1] - w * ty + (z * tx - x * tz);
    r[2] = v[2] - w * tz + (x * ty - y * tx);
}

static void pd_update(const Pd *L, const double *y, double *tau, double *qref) {
    const double *q = y + L->i_q, *w = y + L->i_w;
    double qw = q[0], qx = q[1], qy = q[2], qz = q[3], wx = w[0], wy = w[1], wz = w[2];
    double r[4];
    if (L->lvlh) qmul(y + L->i_qon, L->q_RO, r);
    else memcpy(r, L->q_RO, sizeof r);
    double rw = r[0], rx = r[1], ry = r[2], rz = r[3];
    double ew = rw * qw + rx * qx + ry * qy + rz * qz;
    double ex = rw * qx - rx * qw - ry * qz + rz * qy;
    double ey = rw * qy + rx * qz - ry * qw - rz * qx;
    double ez = rw * qz - rx * qy + ry * qx - rz * qw;
    double kc = ew >= 0.0 ? L->kc : -L->kc;
    double r0 = kc * ex, r1 = kc * ey, r2 = kc * ez;
    double rn2 = r0 * r0 + r1 * r1 + r2 * r2;
    if (rn2 > L->lim2) {
        double f = L->lim / sqrt(rn2);
        r0 = r0 * f, r1 = r1 * f, r2 = r2 * f;
    }
    double v[3];
    if (L->varying) rotate(L->q_RO, y + L->i_won, v);
    else memcpy(v, L->w_RN_R, sizeof v);
    double vx = v[0], vy = v[1], vz = v[2];
    double tx = 2.0 * (ey * vz - ez * vy);
    double ty = 2.0 * (ez * vx - ex * vz);
    double tz = 2.0 * (ex * vy - ey * vx);
    double v0 = r0 + wx - (vx - ew * tx + (ey * tz - ez * ty));
    double v1 = r1 + wy - (vy - ew * ty + (ez * tx - ex * tz));
    double v2 = r2 + wz - (vz - ew * tz + (ex * ty - ey * tx));
    const double (*J)[3] = L->J;
    double c = L->c;
    double t0 = -c * (J[0][0] * v0 + J[0][1] * v1 + J[0][2] * v2);
    double t1 = -c * (J[1][0] * v0 + J[1][1] * v1 + J[1][2] * v2);
    double t2 = -c * (J[2][0] * v0 + J[2][1] * v1 + J[2][2] * v2);
    if (L->gyro) {
        double Hx = J[0][0] * wx + J[0][1] * wy + J[0][2] * wz;
        double Hy = J[1][0] * wx + J[1][1] * wy + J[1][2] * wz;
        double Hz = J[2][0] * wx + J[2][1] * wy + J[2][2] * wz;
        t0 += wy * Hz - wz * Hy;
        t1 += wz * Hx - wx * Hz;
        t2 += wx * Hy - wy * Hx;
    }
    tau[0] = t0, tau[1] = t1, tau[2] = t2;
    qref[0] = rw, qref[1] = rx, qref[2] = ry, qref[3] = rz;
}

/* HELLO -> the law; returns NULL (and the reason in err) when it cannot fly this run */
static int setup(char *text, Pd *L, int *n_y, char *err, size_t nerr) {
    double bw = 0.01, damping = 0.9, slew = 0.005, mean_motion = NAN, J[9] = {0}, q[4] = {1, 0, 0, 0};
    int lvlh = 1, gyro = 1, varies = 0, offset = 0, have_cmd = 0;
    L->i_q = L->i_w = L->i_qon = L->i_won = -1;
    for (char *line = strtok(text, "\n"); line; line = strtok(NULL, "\n")) {
        char key[32], name[64], rest[512] = "";
        if (sscanf(line, "%31s %63s %511[^\n]", key, name, rest) < 2) continue;
        if (!strcmp(key, "stationbed-law") && atoi(name) != VERSION) {
            snprintf(err, nerr, "pd_client.c speaks version %d, HELLO is version %s", VERSION, name);
            return -1;
        } else if (!strcmp(key, "measurement")) {
            int size = atoi(rest);
            if (!strcmp(name, "q_BN")) L->i_q = offset;
            if (!strcmp(name, "omega_BN_B")) L->i_w = offset;
            if (!strcmp(name, "q_ON")) L->i_qon = offset;
            if (!strcmp(name, "omega_ON_O")) L->i_won = offset;
            offset += size;
        } else if (!strcmp(key, "command")) {
            if (!strcmp(name, "tau_B") && atoi(rest) == 3) have_cmd |= 1;
            else if (!strcmp(name, "q_ref_BN") && atoi(rest) == 4) have_cmd |= 2;
            else {
                snprintf(err, nerr, "pd commands a torque: 'command %s %s' is not its frame", name, rest);
                return -1;
            }
        } else if (!strcmp(key, "param")) {
            if (!strcmp(name, "bandwidth")) bw = strtod(rest, NULL);
            else if (!strcmp(name, "damping")) damping = strtod(rest, NULL);
            else if (!strcmp(name, "max_slew_rate")) slew = strtod(rest, NULL);
            else if (!strcmp(name, "reference")) lvlh = !strcmp(rest, "lvlh");
            else if (!strcmp(name, "gyro_compensation")) gyro = !strcmp(rest, "true");
            else if (!strcmp(name, "q_ref")) sscanf(rest, "%lf %lf %lf %lf", &q[0], &q[1], &q[2], &q[3]);
            else {
                snprintf(err, nerr, "pd: unknown parameter '%s'", name);
                return -1;
            }
        } else if (!strcmp(key, "plant")) {
            if (!strcmp(name, "inertia_O_B")) {
                char *p = rest;
                for (int i = 0; i < 9; i++) J[i] = strtod(p, &p);
            } else if (!strcmp(name, "mean_motion")) mean_motion = strtod(rest, NULL);
            else if (!strcmp(name, "lvlh_rate_varies")) varies = strtod(rest, NULL) != 0.0;
        }
    }
    if (L->i_q < 0 || L->i_w < 0 || L->i_qon < 0 || L->i_won < 0 || offset > MAXY || have_cmd != 3) {
        snprintf(err, nerr, "HELLO lacks a field pd reads (q_BN, omega_BN_B, q_ON, omega_ON_O, command tau_B 3, q_ref_BN 4)");
        return -1;
    }
    if (lvlh && isnan(mean_motion)) {
        snprintf(err, nerr, "pd: reference = 'lvlh' needs an [orbit] in the scene");
        return -1;
    }
    double n = sqrt(0.0 + q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]); /* Python's sum() */
    for (int i = 0; i < 4; i++) L->q_RO[i] = q[i] / n;
    L->k = 2.0 * pow(bw, 2.0); /* Python's ** is C's pow */
    L->c = 2.0 * damping * bw;
    for (int i = 0; i < 9; i++) L->J[i / 3][i % 3] = J[i];
    double w_LVLH[3] = {0.0, -(isnan(mean_motion) ? 0.0 : mean_motion), 0.0};
    if (lvlh) rotate(L->q_RO, w_LVLH, L->w_RN_R);
    else L->w_RN_R[0] = L->w_RN_R[1] = L->w_RN_R[2] = 0.0;
    L->lvlh = lvlh;
    L->varying = lvlh && varies;
    L->kc = L->k / L->c;
    L->lim = slew;
    L->lim2 = pow(slew, 2.0);
    L->gyro = gyro;
    *n_y = offset;
    return 0;
}

static void serve(int fd) {
    char head[HEADER];
    int one = 1;
    setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    if (read_all(fd, head, HEADER)) return;
    uint32_t size;
    memcpy(&size, head, 4);
    char *text = calloc(size + 1, 1);
    if (read_all(fd, text, size + 4 - HEADER)) return;
    Pd L;
    int n_y = 0;
    char err[256];
    if (setup(text, &L, &n_y, err, sizeof err)) {
        send_text(fd, ERROR, err);
        return;
    }
    free(text);
    send_text(fd, READY, "stationbed-law 1\ncommand tau_B 3\ncommand q_ref_BN 4\nend\n");
    double frame[HEADER / 8 + MAXY], *y = frame + HEADER / 8, out[7]; /* (aligned for the doubles) */
    char *in = (char *)frame, reply[HEADER + sizeof out];
    size_t n_in = HEADER + 8u * (unsigned)n_y;
    for (;;) {
        /* the header, and the values with it when they came */
        long got = read_spin(fd, in, HEADER, n_in, choose_spin());
        if (got < 0) return; /* stationbed closed the connection */
        uint16_t kind;
        int64_t tick;
        double t;
        memcpy(&size, in, 4);
        memcpy(&kind, in + 6, 2);
        memcpy(&tick, in + 8, 8);
        memcpy(&t, in + 16, 8);
        if (kind == END) return;
        if (kind != MEAS || size + 4 != n_in) return;
        if ((size_t)got < n_in && read_spin(fd, in + got, n_in - (size_t)got, n_in - (size_t)got, W.spin) < 0) return;
        pd_update(&L, y, out, out + 3);
        header(reply, sizeof reply - 4, CMD, tick, t);
        memcpy(reply + HEADER, out, sizeof out);
        if (write_all(fd, reply, sizeof reply)) return;
    }
}

int main(int argc, char **argv) {
    int port = argc > 1 ? atoi(argv[1]) : 5555;
    int srv = socket(AF_INET, SOCK_STREAM, 0), one = 1;
    setsockopt(srv, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    struct sockaddr_in a = {0};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = htons((uint16_t)port);
    if (bind(srv, (struct sockaddr *)&a, sizeof a) || listen(srv, 64)) {
        perror("pd_client: bind");
        return 1;
    }
    socklen_t n = sizeof a;
    getsockname(srv, (struct sockaddr *)&a, &n);
    printf("listening on 127.0.0.1:%d\n", ntohs(a.sin_port));
    fflush(stdout);
    signal(SIGCHLD, SIG_IGN); /* children reaped by the system */
    for (;;) {
        int fd = accept(srv, NULL, NULL);
        if (fd < 0) continue;
        if (fork() == 0) {
            close(srv);
            serve(fd);
            close(fd);
            _exit(0);
        }
        close(fd);
    }
}
