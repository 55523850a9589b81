# A scan of a sphere of radius 0.1 with noise, as an ASCII PLY on stdout: n points on a Fibonacci
# spiral, each moved by Gaussian noise of s per axis (Box-Muller, awk's rand seeded with seed).
# Usage: awk -v n=2000 -v seed=3 -v s=0.002 -f tests/data/noisy_sphere.awk > noisy.ply
BEGIN {
    srand(seed); pi = 3.14159265358979; g = pi * (3 - sqrt(5));
    printf "ply\nformat ascii 1.0\nelement vertex %d\n", n;
    printf "property float x\nproperty float y\nproperty float z\nend_header\n";
    for (i = 0; i < n; i++) {
        y = 1 - 2 * (i + 0.5) / n; r = sqrt(1 - y * y); a = g * i;
        for (k = 0; k < 3; k++) e[k] = s * sqrt(-2 * log(1 - rand())) * cos(2 * pi * rand());
        printf "%.6f %.6f %.6f\n", 0.1 * r * cos(a) + e[0], 0.1 * y + e[1], 0.1 * r * sin(a) + e[2];
    }
}
