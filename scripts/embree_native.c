/* Embree 3 called natively on the incoherent ray sets of `filtrace_accel::bench`
 * (issue 13): the same measurement as scripts/embree_bench.py without embreex's per-call
 * Python/Cython overhead.
 *
 * Input: a triangle file written by `embree_bench.py --native` (little endian):
 *   u32 vertex count V, V x f32 xyz, u32 triangle count T, T x u32 i j k.
 * Scene: one triangle geometry holding every triangle (as embree_bench.py builds it through
 * embreex), RTC_SCENE_FLAG_NONE, build quality MEDIUM (or HIGH with --quality high).
 * Rays: filtrace's `incoherent_rays` bit for bit (SplitMix64, origins uniform in the
 * triangles' bounds, directions uniform on the sphere by Archimedes, t in [0, inf)); the
 * any-hit set is the same rays, also with t_far = inf.
 * Timing, single thread: a warm-up pass, then --repeats passes of rtcIntersect1 /
 * rtcOccluded1 per ray and of rtcIntersect8 / rtcOccluded8 on groups of eight consecutive
 * rays; CPU time of the calling thread (CLOCK_THREAD_CPUTIME_ID) and wall time, best and
 * median. Prints JSON.
 *
 *   embree_native TRIS.bin [--rays N] [--repeats K] [--seed S] [--quality medium|high]
 */
#include <embree3/rtcore.h>
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define MAX_REPEATS 64

static void die(const char *fmt, const char *arg) {
    fprintf(stderr, "embree_native: ");
    fprintf(stderr, fmt, arg);
    fprintf(stderr, "\n");
    exit(2);
}

/* SplitMix64 (Steele, Lea and Flood 2014) exactly as crates/core/src/rng.rs. */
static uint64_t splitmix_next(uint64_t *state) {
    uint64_t z = *state + 0x9e3779b97f4a7c15ull;
    *state = z;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

static float splitmix_f32(uint64_t *state) {
    return (float)(splitmix_next(state) >> 40) * (1.0f / 16777216.0f);
}

typedef struct {
    uint32_t nv, nt;
    float *pos;   /* 3 nv */
    uint32_t *idx; /* 3 nt */
} Mesh;

typedef struct {
    size_t n;
    float *o, *d; /* 3 n each */
} Rays;

static void read_exact(FILE *f, void *dst, size_t size, size_t count, const char *path) {
    if (fread(dst, size, count, f) != count) die("%s: truncated triangle file", path);
}

static Mesh read_mesh(const char *path) {
    Mesh m = {0};
    FILE *f = fopen(path, "rb");
    if (!f) die("cannot open %s", path);
    read_exact(f, &m.nv, 4, 1, path);
    m.pos = malloc((size_t)m.nv * 12 + 12);
    if (!m.pos) die("%s: out of memory for the vertices", path);
    read_exact(f, m.pos, 4, (size_t)m.nv * 3, path);
    read_exact(f, &m.nt, 4, 1, path);
    m.idx = malloc((size_t)m.nt * 12 + 12);
    if (!m.idx) die("%s: out of memory for the triangles", path);
    read_exact(f, m.idx, 4, (size_t)m.nt * 3, path);
    if (fgetc(f) != EOF) die("%s: trailing bytes after the triangles", path);
    fclose(f);
    for (size_t i = 0; i < (size_t)m.nt * 3; i++)
        if (m.idx[i] >= m.nv) die("%s: a triangle index is out of range", path);
    if (m.nt == 0) die("%s: no triangles", path);
    return m;
}

/* filtrace_accel::bench::incoherent_rays: the same draws in the same order. */
static Rays incoherent_rays(const Mesh *m, size_t n, uint64_t seed) {
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (size_t i = 0; i < (size_t)m->nt * 3; i++)
        for (int a = 0; a < 3; a++) {
            float p = m->pos[3 * (size_t)m->idx[i] + a];
            lo[a] = fminf(lo[a], p);
            hi[a] = fmaxf(hi[a], p);
        }
    Rays r = {n, malloc(n * 12 + 12), malloc(n * 12 + 12)};
    if (!r.o || !r.d) die("out of memory for %s rays", "the");
    uint64_t s = seed;
    for (size_t i = 0; i < n; i++) {
        for (int a = 0; a < 3; a++) r.o[3 * i + a] = lo[a] + splitmix_f32(&s) * (hi[a] - lo[a]);
        float z = 1.0f - 2.0f * splitmix_f32(&s);
        float rad = sqrtf(fmaxf(1.0f - z * z, 0.0f));
        float phi = 2.0f * (float)M_PI * splitmix_f32(&s);
        r.d[3 * i] = rad * cosf(phi);
        r.d[3 * i + 1] = rad * sinf(phi);
        r.d[3 * i + 2] = z;
    }
    return r;
}

static RTCScene build_scene(RTCDevice dev, const Mesh *m, enum RTCBuildQuality q) {
    RTCScene scene = rtcNewScene(dev);
    rtcSetSceneFlags(scene, RTC_SCENE_FLAG_NONE);
    rtcSetSceneBuildQuality(scene, q);
    RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetGeometryBuildQuality(g, q);
    float *v = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 12, m->nv);
    uint32_t *t = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 12, m->nt);
    if (!v || !t) die("rtcSetNewGeometryBuffer failed (%s)", "out of memory?");
    memcpy(v, m->pos, (size_t)m->nv * 12);
    memcpy(t, m->idx, (size_t)m->nt * 12);
    rtcCommitGeometry(g);
    rtcAttachGeometry(scene, g);
    rtcReleaseGeometry(g);
    rtcCommitScene(scene);
    return scene;
}

static void init_ray(struct RTCRay *ray, const Rays *r, size_t i) {
    ray->org_x = r->o[3 * i], ray->org_y = r->o[3 * i + 1], ray->org_z = r->o[3 * i + 2];
    ray->dir_x = r->d[3 * i], ray->dir_y = r->d[3 * i + 1], ray->dir_z = r->d[3 * i + 2];
    ray->tnear = 0.0f, ray->tfar = INFINITY, ray->time = 0.0f;
    ray->mask = 0xFFFFFFFFu, ray->id = 0, ray->flags = 0;
}

/* One pass; returns the number of rays that hit. */
static size_t pass_1(RTCScene scene, const Rays *r, int any) {
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    size_t hits = 0;
    for (size_t i = 0; i < r->n; i++) {
        struct RTCRayHit rh;
        init_ray(&rh.ray, r, i);
        if (any) {
            rtcOccluded1(scene, &ctx, &rh.ray);
            hits += rh.ray.tfar < 0.0f; /* a hit sets tfar to -inf */
        } else {
            rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
            rtcIntersect1(scene, &ctx, &rh);
            hits += rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
        }
    }
    return hits;
}

/* One pass in packets of eight consecutive rays (the last one masked). */
static size_t pass_8(RTCScene scene, const Rays *r, int any) {
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    size_t hits = 0;
    for (size_t b = 0; b < r->n; b += 8) {
        RTC_ALIGN(32) struct RTCRayHit8 p;
        RTC_ALIGN(32) int valid[8];
        for (int k = 0; k < 8; k++) {
            size_t i = b + k < r->n ? b + k : b;
            valid[k] = b + k < r->n ? -1 : 0;
            p.ray.org_x[k] = r->o[3 * i], p.ray.org_y[k] = r->o[3 * i + 1], p.ray.org_z[k] = r->o[3 * i + 2];
            p.ray.dir_x[k] = r->d[3 * i], p.ray.dir_y[k] = r->d[3 * i + 1], p.ray.dir_z[k] = r->d[3 * i + 2];
            p.ray.tnear[k] = 0.0f, p.ray.tfar[k] = INFINITY, p.ray.time[k] = 0.0f;
            p.ray.mask[k] = 0xFFFFFFFFu, p.ray.id[k] = k, p.ray.flags[k] = 0;
            p.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
        }
        if (any)
            rtcOccluded8(valid, scene, &ctx, &p.ray);
        else
            rtcIntersect8(valid, scene, &ctx, &p);
        for (int k = 0; k < 8; k++)
            if (valid[k]) hits += any ? p.ray.tfar[k] < 0.0f : p.hit.geomID[k] != RTC_INVALID_GEOMETRY_ID;
    }
    return hits;
}

static double seconds(clockid_t clock) {
    struct timespec ts;
    clock_gettime(clock, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

static int cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static double median(double *v, int n) {
    qsort(v, n, sizeof *v, cmp_double);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/* Warm-up, then `repeats` timed passes; prints one JSON object (no trailing newline). */
static void measure(const char *name, RTCScene scene, const Rays *r, int width, int any, int repeats) {
    size_t (*pass)(RTCScene, const Rays *, int) = width == 8 ? pass_8 : pass_1;
    size_t hits = pass(scene, r, any);
    double cpu[MAX_REPEATS], wall[MAX_REPEATS];
    for (int k = 0; k < repeats; k++) {
        double c0 = seconds(CLOCK_THREAD_CPUTIME_ID), w0 = seconds(CLOCK_MONOTONIC);
        if (pass(scene, r, any) != hits) die("%s: the hit count changed between passes", name);
        wall[k] = seconds(CLOCK_MONOTONIC) - w0;
        cpu[k] = seconds(CLOCK_THREAD_CPUTIME_ID) - c0;
    }
    double n = (double)r->n / 1e6;
    double best_cpu = cpu[0], best_wall = wall[0];
    for (int k = 1; k < repeats; k++) best_cpu = fmin(best_cpu, cpu[k]), best_wall = fmin(best_wall, wall[k]);
    printf("  \"%s\": {\"mrays_per_cpu_s\": %.4f, \"mrays_per_cpu_s_median\": %.4f, \"mrays\": %.4f, "
           "\"mrays_median\": %.4f, \"hit_fraction\": %.6f}",
           name, n / best_cpu, n / median(cpu, repeats), n / best_wall, n / median(wall, repeats),
           (double)hits / (double)r->n);
}

static unsigned long long parse_u64(const char *flag, const char *s) {
    char *end;
    errno = 0;
    unsigned long long v = strtoull(s, &end, 10);
    if (errno || *end || end == s || s[0] == '-') die("bad value for %s", flag);
    return v;
}

int main(int argc, char **argv) {
    const char *path = NULL;
    size_t n = 1 << 20;
    int repeats = 3;
    uint64_t seed = 7;
    enum RTCBuildQuality quality = RTC_BUILD_QUALITY_MEDIUM;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        int has_value = i + 1 < argc;
        if (!strcmp(a, "--rays") && has_value) n = parse_u64(a, argv[++i]);
        else if (!strcmp(a, "--repeats") && has_value) repeats = (int)parse_u64(a, argv[++i]);
        else if (!strcmp(a, "--seed") && has_value) seed = parse_u64(a, argv[++i]);
        else if (!strcmp(a, "--quality") && has_value) {
            const char *q = argv[++i];
            if (!strcmp(q, "medium")) quality = RTC_BUILD_QUALITY_MEDIUM;
            else if (!strcmp(q, "high")) quality = RTC_BUILD_QUALITY_HIGH;
            else die("--quality is medium or high, not %s", q);
        } else if (a[0] != '-' && !path) path = a;
        else die("unknown or incomplete argument %s (usage: embree_native TRIS.bin [--rays N] "
                 "[--repeats K] [--seed S] [--quality medium|high])", a);
    }
    if (!path) die("%s", "usage: embree_native TRIS.bin [--rays N] [--repeats K] [--seed S] [--quality medium|high]");
    if (n == 0) die("%s", "--rays must be at least 1");
    if (repeats < 1 || repeats > MAX_REPEATS) die("%s", "--repeats must be in 1..64");

    Mesh m = read_mesh(path);
    Rays r = incoherent_rays(&m, n, seed);
    RTCDevice dev = rtcNewDevice(NULL);
    if (!dev) die("%s", "rtcNewDevice failed");
    double w0 = seconds(CLOCK_MONOTONIC);
    RTCScene scene = build_scene(dev, &m, quality);
    double build_s = seconds(CLOCK_MONOTONIC) - w0;
    if (rtcGetDeviceError(dev) != RTC_ERROR_NONE) die("%s", "Embree reported an error building the scene");

    printf("{\n  \"embree\": \"%ld.%ld.%ld\",\n  \"api\": \"embree3 C, native\",\n",
           rtcGetDeviceProperty(dev, RTC_DEVICE_PROPERTY_VERSION_MAJOR),
           rtcGetDeviceProperty(dev, RTC_DEVICE_PROPERTY_VERSION_MINOR),
           rtcGetDeviceProperty(dev, RTC_DEVICE_PROPERTY_VERSION_PATCH));
    printf("  \"build_quality\": \"%s\",\n  \"triangles\": %u,\n  \"rays\": %zu,\n  \"seed\": %llu,\n",
           quality == RTC_BUILD_QUALITY_HIGH ? "high" : "medium", m.nt, n, (unsigned long long)seed);
    printf("  \"repeats\": %d,\n  \"build_s\": %.4f,\n", repeats, build_s);
    measure("incoherent_closest", scene, &r, 1, 0, repeats);
    printf(",\n");
    measure("incoherent_any", scene, &r, 1, 1, repeats);
    printf(",\n");
    measure("packet8_incoherent_closest", scene, &r, 8, 0, repeats);
    printf(",\n");
    measure("packet8_incoherent_any", scene, &r, 8, 1, repeats);
    printf("\n}\n");
    rtcReleaseScene(scene);
    rtcReleaseDevice(dev);
    return 0;
}
