/* Loads a binary wheel's C model and stepping core with dlopen, as cffi and ctypes do, and calls the
 * model's kinematics on a sweep of poses: compiled for aarch64 and run under qemu-aarch64, it shows
 * that the aarch64 wheel's libraries load and compute what the x86_64 wheel's do
 * (tests/project/test_wheel.py).
 *
 * usage: wheel_model_host MODEL_LIBRARY STEPPER_LIBRARY N
 * prints: one line per pose i < N with %.17g of q[3] (inverse kinematics), x[3] (forward of q),
 * dq[3] (joint velocity) and dx[3] (task velocity of dq), then the last line "stepper ok". */
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>

typedef void (*inverse_f)(double X, double Z, double B, double L1, double q[3]);
typedef int (*forward_f)(const double q[3], double L1, double x[3], double *arg);
typedef void (*joint_velocity_f)(double B, double dX, double dZ, double dB, double L1, double dq[3]);
typedef void (*task_velocity_f)(double B, const double dq[3], double L1, double dx[3]);

static void *open_or_die(const char *path)
{
    void *h = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!h) {
        fprintf(stderr, "dlopen %s: %s\n", path, dlerror());
        exit(2);
    }
    return h;
}

static void *symbol_or_die(void *h, const char *name)
{
    void *f = dlsym(h, name);
    if (!f) {
        fprintf(stderr, "dlsym %s: %s\n", name, dlerror());
        exit(2);
    }
    return f;
}

int main(int argc, char **argv)
{
    if (argc != 4) {
        fprintf(stderr, "usage: %s MODEL_LIBRARY STEPPER_LIBRARY N\n", argv[0]);
        return 2;
    }
    void *model = open_or_die(argv[1]);
    inverse_f inverse = (inverse_f)symbol_or_die(model, "tapmp_inverse");
    forward_f forward = (forward_f)symbol_or_die(model, "tapmp_forward");
    joint_velocity_f joint_velocity = (joint_velocity_f)symbol_or_die(model, "tapmp_joint_velocity");
    task_velocity_f task_velocity = (task_velocity_f)symbol_or_die(model, "tapmp_task_velocity");
    int n = atoi(argv[3]);
    const double L1 = 0.1;  /* [m], a link length of the paper's order */
    for (int i = 0; i < n; i++) {
        /* poses across the workspace: X, Z [m] within +-5 mm, B [rad] within +-0.3 */
        double X = 0.005 * ((i % 17) / 8.0 - 1.0), Z = 0.005 * ((i % 13) / 6.0 - 1.0), B = 0.3 * ((i % 11) / 5.0 - 1.0);
        double q[3], x[3], dq[3], dx[3], arg;
        inverse(X, Z, B, L1, q);
        if (!forward(q, L1, x, &arg)) {
            fprintf(stderr, "forward kinematics failed at pose %d\n", i);
            return 1;
        }
        joint_velocity(B, 0.01 * X, 0.02 * Z, 0.1 * B, L1, dq);
        task_velocity(B, dq, L1, dx);
        printf("%.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g\n",
               q[0], q[1], q[2], x[0], x[1], x[2], dq[0], dq[1], dq[2], dx[0], dx[1], dx[2]);
    }
    symbol_or_die(open_or_die(argv[2]), "tapmp_advance");
    printf("stepper ok\n");
    return 0;
}
