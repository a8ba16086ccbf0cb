component orthoglidekins "Orthoglide kinematics with the geometry orthocal identified";

description """
Kinematics of an Orthoglide-type machine (three orthogonal linear axes x, y, z whose
carriages drive parallelogram legs to the tool point P) with the geometry orthocal
identifies: joint offsets, leg lengths, tilted axes, axes that do not meet (orthocal's
docs/model.md). [KINS] KINEMATICS = orthoglidekins, JOINTS = 3, coordinates XYZ. Joint n
is rho of axis n as orthocal commands it: absolute, the mechanical zero (P = 0) at rho = L.
World X, Y, Z is P in mm.

Geometry pins (float in, read at every call): orthoglidekins.leg-length-x|y|z (mm, L + dL),
orthoglidekins.tilt-yx|zx|zy (mrad), orthoglidekins.gap-xy|xz|yz (mm),
orthoglidekins.drho-x|y|z (mm); by default the paper's machine (legs of 310.25 mm, the rest
0). They exist once motion has loaded (its first kinematicsType() call makes them): setp
them in a HAL file listed after the one that loads motion, as orthocal export
--kinematics writes it. Build once: sudo halcompile --install orthoglidekins.comp
""";

// halcompile wants one declared pin; the kinematics' own pins cannot be declared, because
// the kinematics functions get no instance to read them from (made in og_setup instead).
pin out bit unused = 0 "not used: the geometry pins are orthoglidekins.leg-length-x etc.";
option singleton yes;
license "MIT";
author "orthocal";
;;

#include "rtapi_math.h"
#include "kinematics.h"

/* orthocal maths: begin */
/* Pure maths, tested against orthocal/kinematics.py outside LinuxCNC
   (tests/test_kins_c.py): plain doubles, the caller provides <math.h> (sqrt, fabs, fmax,
   isfinite), and OG_API is how the test exports og_inverse and og_forward. */
#ifndef OG_API
#define OG_API static
#endif

/* The same steps as orthocal.kinematics.solve_spheres, so that C and Python agree. */
#define OG_NEWTON_TOL 1e-12 /* mm: Newton stops when its step is below this */
#define OG_NEWTON_MAX_STEPS 30
/* Far from the workspace the legs' Jacobian is ill-conditioned and rounding alone makes
   steps of a few 1e-12 mm that never shrink: a step below this (mm) that is no smaller
   than the one before also ends the iteration (Newton's quadratic convergence is over). */
#define OG_ROUNDING_FLOOR 1e-9
/* The legs' unit vectors P - A_i span a volume of -1 at the mechanical zero (every leg
   along -e_i), 0 at a parallel singularity and > 0 in the mirrored assembly mode; within
   OG_MIN_VOLUME of 0 the Jacobian cannot be trusted. */
#define OG_MIN_VOLUME 1e-9

struct og_geometry {
    double leg_length[3]; /* L_i = L + dL_i, mm */
    double tilt[3];       /* t_yx, t_zx, t_zy, mrad */
    double gap[3];        /* g_xy, g_xz, g_yz, mm */
    double drho[3];       /* joint offsets: the carriage of axis i stands at rho_i + drho_i */
};

static double og_dot(const double a[3], const double b[3])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

static void og_cross(const double a[3], const double b[3], double out[3])
{
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

/* Axis directions u_i (model.md, "Extended model": u_x = e_x, u_y leans toward +x by t_yx,
   u_z toward +x by t_zx and +y by t_zy) and points c_i of the axes' lines (model.md, "Axes
   that do not meet": the origin midway between each pair of axes). Non-zero when a value is
   not finite: no pose may come out of such a geometry. */
static int og_axes(const struct og_geometry *g, double u[3][3], double c[3][3])
{
    const double t_yx = g->tilt[0] * 1e-3, t_zx = g->tilt[1] * 1e-3, t_zy = g->tilt[2] * 1e-3;
    const double h_xy = g->gap[0] / 2, h_xz = g->gap[1] / 2, h_yz = g->gap[2] / 2;
    const double rows[3][3] = {{1, 0, 0}, {t_yx, 1, 0}, {t_zx, t_zy, 1}};
    const double points[3][3] = {{0, h_xz, h_xy}, {h_yz, 0, -h_xy}, {-h_yz, -h_xz, 0}};
    int i, j;
    for (i = 0; i < 3; i++) {
        const double norm = sqrt(og_dot(rows[i], rows[i]));
        if (!isfinite(norm) || !isfinite(g->leg_length[i]) || !isfinite(g->drho[i])
            || g->leg_length[i] <= 0)
            return -1;
        for (j = 0; j < 3; j++) {
            u[i][j] = rows[i][j] / norm;
            c[i][j] = points[i][j];
        }
    }
    return 0;
}

/* Inverse kinematics, explicit (model.md, "Machine and parameters", (1')): |P - A_i| = L_i
   with A_i = c_i + q_i u_i is a quadratic in q_i; with d_i = P - c_i its working root (the
   carriage beyond P) is q_i = u_i.d_i + sqrt(L_i^2 - |d_i - (u_i.d_i) u_i|^2), and
   rho_i = q_i - drho_i. A negative radicand means P is beyond leg i's reach: an error,
   never a NaN joint. rho is written only on success. */
OG_API int og_inverse(const struct og_geometry *g, const double p[3], double rho[3])
{
    double u[3][3], c[3][3], out[3];
    int i, j;
    if (og_axes(g, u, c) != 0 || !isfinite(p[0]) || !isfinite(p[1]) || !isfinite(p[2]))
        return -1;
    for (i = 0; i < 3; i++) {
        double d[3], perp[3], along, radicand;
        for (j = 0; j < 3; j++)
            d[j] = p[j] - c[i][j];
        along = og_dot(u[i], d);
        for (j = 0; j < 3; j++)
            perp[j] = d[j] - along * u[i][j];
        radicand = g->leg_length[i] * g->leg_length[i] - og_dot(perp, perp);
        if (!(radicand >= 0))
            return -1;
        out[i] = along + sqrt(radicand) - g->drho[i];
    }
    for (i = 0; i < 3; i++)
        rho[i] = out[i];
    return 0;
}

/* The closed form of (1) for carriages at q_i e_i (model.md, "Machine and parameters",
   orthocal.kinematics._forward_orthogonal): s = |P|^2 solves A s^2 + B s + C = 0, the
   working branch is the smaller root (P near the origin at the mechanical zero), taken as
   2C / (-B + sqrt(disc)) to avoid cancellation. Outside the assembly domain (disc < 0, or
   B >= 0: no positive smaller root) non-zero. */
static int og_forward_orthogonal(const double q[3], const double L[3], double p[3])
{
    double k[3], A = 0, B = -1, C = 0, disc, s;
    int i;
    for (i = 0; i < 3; i++) {
        const double w = 1.0 / (4.0 * q[i] * q[i]);
        k[i] = q[i] * q[i] - L[i] * L[i];
        A += w;
        B += 2.0 * k[i] * w;
        C += k[i] * k[i] * w;
    }
    disc = B * B - 4.0 * A * C;
    if (!(disc >= 0) || !(B < 0))
        return -1;
    s = 2.0 * C / (-B + sqrt(disc));
    for (i = 0; i < 3; i++)
        p[i] = (s + k[i]) / (2.0 * q[i]);
    return 0;
}

/* Rows d_i = P - A_i, A_i = c_i + q_i u_i: the legs, from their carriages to P. */
static void og_legs(const double u[3][3], const double c[3][3], const double q[3],
                    const double pose[3], double d[3][3])
{
    int i, j;
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++)
            d[i][j] = pose[j] - c[i][j] - q[i] * u[i][j];
}

/* One Newton step on F_i(P) = |P - A_i|^2 - L_i^2, whose Jacobian has rows 2 d_i:
   step = J^-1 F by the cross products of the rows (the inverse of a 3x3 matrix with rows
   a, b, c has columns b x c, c x a, a x b over a.(b x c)). Non-zero where the legs are
   near coplanar (a parallel singularity: no step to trust). */
static int og_newton_step(const double d[3][3], const double L[3], double step[3])
{
    double cols[3][3], f[3], volume;
    int i, j;
    og_cross(d[1], d[2], cols[0]);
    og_cross(d[2], d[0], cols[1]);
    og_cross(d[0], d[1], cols[2]);
    volume = og_dot(d[0], cols[0]);
    if (!(fabs(volume) > OG_MIN_VOLUME * L[0] * L[1] * L[2]))
        return -1;
    for (i = 0; i < 3; i++)
        f[i] = og_dot(d[i], d[i]) - L[i] * L[i];
    for (j = 0; j < 3; j++)
        step[j] = (f[0] * cols[0][j] + f[1] * cols[1][j] + f[2] * cols[2][j]) / (2.0 * volume);
    return 0;
}

/* Whether the legs d make a pose of the working assembly mode, the mechanical zero's:
   their volume below -OG_MIN_VOLUME (not the mirror image across the carriages' plane,
   which the same joints also close), and every carriage beyond P (-u_i.d_i > 0, the root
   the inverse takes), so that the inverse gives the same joints back. */
static int og_working_mode(const double u[3][3], const double d[3][3], const double L[3])
{
    double cross[3];
    int i;
    og_cross(d[1], d[2], cross);
    if (!(og_dot(d[0], cross) < -OG_MIN_VOLUME * L[0] * L[1] * L[2]))
        return 0;
    for (i = 0; i < 3; i++)
        if (!(-og_dot(u[i], d[i]) > 0))
            return 0;
    return 1;
}

/* Forward kinematics (model.md, "Machine and parameters": (1') has no closed form): Newton
   on the three sphere equations from the closed form of (1) for the same q and L, as
   orthocal.kinematics.solve_spheres, until the step is below OG_NEWTON_TOL (or at the
   rounding floor). An error (never a pose) outside the assembly domain: the start fails,
   a singular step, no convergence within OG_NEWTON_MAX_STEPS, a non-finite value, or an
   answer off the working mode. p is written only on success. */
OG_API int og_forward(const struct og_geometry *g, const double rho[3], double p[3])
{
    double u[3][3], c[3][3], q[3], pose[3], d[3][3], previous = 0;
    int i, n;
    if (og_axes(g, u, c) != 0)
        return -1;
    for (i = 0; i < 3; i++) {
        q[i] = rho[i] + g->drho[i];
        if (!isfinite(q[i]) || q[i] == 0)
            return -1;
    }
    if (og_forward_orthogonal(q, g->leg_length, pose) != 0)
        return -1;
    for (n = 0; n < OG_NEWTON_MAX_STEPS; n++) {
        double step[3], size;
        og_legs(u, c, q, pose, d);
        if (og_newton_step(d, g->leg_length, step) != 0)
            return -1;
        for (i = 0; i < 3; i++)
            pose[i] -= step[i];
        if (!isfinite(pose[0]) || !isfinite(pose[1]) || !isfinite(pose[2]))
            return -1;
        size = fmax(fabs(step[0]), fmax(fabs(step[1]), fabs(step[2])));
        if (size < OG_NEWTON_TOL || (n > 0 && size < OG_ROUNDING_FLOOR && size >= previous))
            break;
        previous = size;
    }
    og_legs(u, c, q, pose, d);
    if (n == OG_NEWTON_MAX_STEPS || !og_working_mode(u, d, g->leg_length))
        return -1;
    for (i = 0; i < 3; i++)
        p[i] = pose[i];
    return 0;
}
/* orthocal maths: end */

/* The geometry pins: the kinematics functions are called by motion with no instance of
   this component, so they reach their pins through this pointer (as LinuxCNC's
   userkins.comp does). NULL until every pin exists. */
static struct og_pins {
    hal_float_t *leg_length[3], *tilt[3], *gap[3], *drho[3];
} *og_pins;

/* Make the pins, with the paper's machine as their defaults (docs/model.md, "Test
   postures": L = 310.25 mm, every other value 0), so that an unset pin is the nominal
   machine. The component is made ready again whatever happens, or LinuxCNC would wait. */
static void og_setup(void)
{
    static const char *const names[4][3] = {{"leg-length-x", "leg-length-y", "leg-length-z"},
                                            {"tilt-yx", "tilt-zx", "tilt-zy"},
                                            {"gap-xy", "gap-xz", "gap-yz"},
                                            {"drho-x", "drho-y", "drho-z"}};
    struct og_pins *pins;
    int i, r = 0;
    if (comp_id < 0 || hal_set_unready(comp_id) != 0)
        return;
    pins = hal_malloc(sizeof(*pins));
    for (i = 0; pins && i < 3; i++) {
        hal_float_t **made[4] = {&pins->leg_length[i], &pins->tilt[i], &pins->gap[i],
                                 &pins->drho[i]};
        int n;
        for (n = 0; n < 4 && r == 0; n++) {
            r = hal_pin_float_newf(HAL_IN, made[n], comp_id, "orthoglidekins.%s", names[n][i]);
            if (r == 0)
                **made[n] = n == 0 ? 310.25 : 0.0;
        }
    }
    hal_ready(comp_id);
    if (pins && r == 0)
        og_pins = pins;
    else
        rtapi_print_msg(RTAPI_MSG_ERR, "orthoglidekins: cannot make the geometry pins\n");
}

/* The pins as they stand now (a setp takes effect at the next call). Non-zero without
   pins, so that no pose comes from a geometry never read. */
static int og_read_pins(struct og_geometry *g)
{
    int i;
    if (!og_pins)
        return -1;
    for (i = 0; i < 3; i++) {
        g->leg_length[i] = *og_pins->leg_length[i];
        g->tilt[i] = *og_pins->tilt[i];
        g->gap[i] = *og_pins->gap[i];
        g->drho[i] = *og_pins->drho[i];
    }
    return 0;
}

KINS_NOT_SWITCHABLE
EXPORT_SYMBOL(kinematicsType);
EXPORT_SYMBOL(kinematicsForward);
EXPORT_SYMBOL(kinematicsInverse);
EXPORT_SYMBOL(kinematicsHome);

/* Motion calls this first, at loadrt motmod: the moment to make the pins (userkins.comp).
   BOTH: a real forward and inverse, the forward an iteration (not called per cycle). */
KINEMATICS_TYPE kinematicsType(void)
{
    static int made;
    if (!made) {
        made = 1;
        og_setup();
    }
    return KINEMATICS_BOTH;
}

/* Motion counts result < 0 as failure (control.c): our errors are -1, and on an error
   the pose is left as it was, never overwritten by a wrong one. */
int kinematicsForward(const double *joints, EmcPose *pos, const KINEMATICS_FORWARD_FLAGS *fflags,
                      KINEMATICS_INVERSE_FLAGS *iflags)
{
    struct og_geometry g;
    double p[3];
    (void)fflags;
    (void)iflags;
    if (og_read_pins(&g) != 0 || og_forward(&g, joints, p) != 0)
        return -1;
    pos->tran.x = p[0];
    pos->tran.y = p[1];
    pos->tran.z = p[2];
    pos->a = pos->b = pos->c = 0;
    pos->u = pos->v = pos->w = 0;
    return 0;
}

/* docs/design.md, "The geometry in the controller", (K1): the joints are the exact
   inverse of the identified machine; an error where a leg cannot reach. */
int kinematicsInverse(const EmcPose *pos, double *joints, const KINEMATICS_INVERSE_FLAGS *iflags,
                      KINEMATICS_FORWARD_FLAGS *fflags)
{
    struct og_geometry g;
    const double p[3] = {pos->tran.x, pos->tran.y, pos->tran.z};
    (void)iflags;
    (void)fflags;
    if (og_read_pins(&g) != 0 || og_inverse(&g, p, joints) != 0)
        return -1;
    return 0;
}

/* The pose of the joints at home: the forward kinematics of them (motion of 2.9 does
   not call it; the API declares it). */
int kinematicsHome(EmcPose *world, double *joints, KINEMATICS_FORWARD_FLAGS *fflags,
                   KINEMATICS_INVERSE_FLAGS *iflags)
{
    *fflags = 0;
    *iflags = 0;
    return kinematicsForward(joints, world, fflags, iflags);
}
