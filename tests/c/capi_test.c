/* The C ABI as a C program uses it: compiled with -std=c11 -Wall -Wextra -Werror against
 * include/isobar.h. One SPH particle's isosurface is a sphere of known radius; bad input
 * and cancellation must come back as status codes with messages, never a crash. */
#include "isobar.h"

#include <math.h>
#include <stdio.h>
#include <stddef.h>
#include <string.h>

static int failures = 0;
#define CHECK(cond, ...)                                                  \
    do {                                                                  \
        if (!(cond)) {                                                    \
            fprintf(stderr, "FAIL %s:%d: ", __FILE__, __LINE__);          \
            fprintf(stderr, __VA_ARGS__);                                 \
            fprintf(stderr, " (last error: %s)\n", isobar_last_error_message()); \
            failures++;                                                   \
        }                                                                 \
    } while (0)

static const double PI = 3.14159265358979323846;

/* Cubic spline W(r, h), written out here independently of the library. */
static double cubic(double r, double h) {
    double q = r / h, s = 1.0 / (PI * h * h * h);
    if (q < 1.0) return s * (1.0 - 1.5 * q * q + 0.75 * q * q * q);
    if (q < 2.0) return s * 0.25 * (2.0 - q) * (2.0 - q) * (2.0 - q);
    return 0.0;
}

static int progress_calls = 0;
static int32_t count_progress(void *user, double fraction, const char *phase) {
    (void)user;
    (void)phase;
    if (fraction < 0.0 || fraction > 1.0) failures++;
    progress_calls++;
    return 0;
}

static int32_t cancel_at_once(void *user, double fraction, const char *phase) {
    (void)fraction;
    (void)phase;
    *(int *)user += 1;
    return 1;
}

/* argv[1], when given, is what `isobar ... --backend auto` printed on this machine after
 * "backend auto: running on the CPU (" ("" when it printed no such line): the note must
 * be the same text, so every host that shows it tells the user what the CLI does. */
int main(int argc, char **argv) {
    CHECK(isobar_abi_version() == ISOBAR_ABI_VERSION, "ABI %u", isobar_abi_version());
    CHECK(strlen(isobar_version()) > 0, "version");

    {
        const char *note = NULL;
        CHECK(isobar_auto_backend_note(&note) == ISOBAR_STATUS_OK, "auto backend note");
        CHECK(note != NULL, "auto backend note is NULL");
        if (note != NULL && argc > 1)
            CHECK(strcmp(note, argv[1]) == 0, "auto backend note '%s' differs from the CLI's '%s'", note, argv[1]);
        CHECK(isobar_auto_backend_note(NULL) == ISOBAR_STATUS_ERR_INVALID_ARGUMENT, "NULL note pointer");
        CHECK(strstr(isobar_last_error_message(), "note") != NULL, "message names note: %s",
              isobar_last_error_message());
    }

    const double centre[3] = {0.5, -0.25, 1.0};
    const double h = 0.4, value = 3.0, volume = 0.7;
    IsobarParticles *particles = NULL;
    CHECK(isobar_particles_create(centre, 1, &particles) == ISOBAR_STATUS_OK, "create");
    CHECK(isobar_particles_add_array(particles, "a", &value, 1, 1) == ISOBAR_STATUS_OK, "add a");
    CHECK(isobar_particles_add_array(particles, "vol", &volume, 1, 1) == ISOBAR_STATUS_OK, "add vol");
    CHECK(isobar_particles_count(particles) == 1, "count");
    CHECK(isobar_particles_array_count(particles) == 2, "array count");

    IsobarSphParams params;
    CHECK(isobar_sph_params_default(&params) == ISOBAR_STATUS_OK, "defaults");
    CHECK(params.struct_size == sizeof(IsobarSphParams), "struct_size");
    const double iso = 0.5 * value * volume * cubic(0.0, h);
    params.h = h;
    params.field = "a";
    params.volume_array = "vol";
    params.isovalues = &iso;
    params.isovalue_count = 1;
    params.trim = 0;
    params.grid_factor = 0.1;

    IsobarSurface *surface = NULL;
    CHECK(isobar_sph_extract(particles, &params, count_progress, NULL, &surface) == ISOBAR_STATUS_OK, "extract");
    CHECK(progress_calls > 3, "progress called %d times", progress_calls);
    size_t nv = isobar_surface_vertex_count(surface), nt = isobar_surface_triangle_count(surface);
    CHECK(nv > 100 && nt > 200, "%zu vertices, %zu triangles", nv, nt);
    const double *xyz = isobar_surface_positions(surface);
    const float *normals = isobar_surface_normals(surface);
    const uint32_t *tris = isobar_surface_triangles(surface);
    CHECK(xyz && normals && tris, "arrays");
    double worst = 0.0;
    for (size_t i = 0; i < nv; i++) {
        double d[3] = {xyz[3 * i] - centre[0], xyz[3 * i + 1] - centre[1], xyz[3 * i + 2] - centre[2]};
        double r = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        double f = value * volume * cubic(r, h);
        if (fabs(f - iso) > worst) worst = fabs(f - iso);
        double radial = (d[0] * normals[3 * i] + d[1] * normals[3 * i + 1] + d[2] * normals[3 * i + 2]) / r;
        CHECK(radial > 0.9999, "normal %zu not radial (%f)", i, radial);
    }
    CHECK(worst <= 1e-6 * iso, "max |F - iso| = %g", worst);
    for (size_t t = 0; t < 3 * nt; t++) CHECK(tris[t] < nv, "index %u out of range", tris[t]);

    IsobarStats stats;
    memset(&stats, 0, sizeof stats);
    stats.struct_size = sizeof stats;
    CHECK(isobar_surface_stats(surface, &stats) == ISOBAR_STATUS_OK, "stats");
    CHECK(stats.triangles == nt && stats.vertices == nv, "stats counts");
    CHECK(stats.seed_cells > 0 && stats.cache_hit_ratio > 0.0, "stats figures");

    const char *name = NULL;
    size_t components = 0;
    const double *weights = NULL;
    CHECK(isobar_surface_attribute(surface, 0, &name, &components, &weights) == ISOBAR_STATUS_OK, "attribute");
    CHECK(name && strcmp(name, "SumOfWeights") == 0 && components == 1 && weights, "SumOfWeights");
    CHECK(isobar_surface_attribute(surface, 99, &name, &components, &weights) == ISOBAR_STATUS_ERR_INVALID_ARGUMENT, "index 99");
    CHECK(strcmp(isobar_surface_warnings(surface), "") == 0, "warnings on a sound surface: %s",
          isobar_surface_warnings(surface));
    CHECK(strcmp(isobar_surface_warnings(NULL), "") == 0, "warnings of NULL");
    isobar_surface_free(surface);

    /* Above the particle's peak the field is never crossed: an empty surface, and a
     * warning saying so, one line per isovalue. */
    {
        const double above[2] = {2.0 * value * volume * cubic(0.0, h), 3.0 * value * volume * cubic(0.0, h)};
        params.isovalues = above;
        params.isovalue_count = 2;
        IsobarSurface *empty = NULL;
        CHECK(isobar_sph_extract(particles, &params, NULL, NULL, &empty) == ISOBAR_STATUS_OK, "extract above the peak");
        CHECK(isobar_surface_triangle_count(empty) == 0, "no triangles above the peak");
        const char *warnings = isobar_surface_warnings(empty);
        const char *newline = strchr(warnings, '\n');
        CHECK(strncmp(warnings, "no surface at isovalue ", 23) == 0 && newline &&
                  strncmp(newline + 1, "no surface at isovalue ", 23) == 0 && !strchr(newline + 1, '\n'),
              "two warnings, one a line: '%s'", warnings);
        isobar_surface_free(empty);
        params.isovalues = &iso;
        params.isovalue_count = 1;
    }

    /* The adaptive 3-level surface of the same particle: every vertex within the
     * bisection accuracy (finest cell / 2^n, n = the level-3 halvings) of the sphere
     * where the kernel sum equals iso, and one isovalue only. */
    {
        double lo = 0.0, hi = 2.0 * h;
        for (int k = 0; k < 200; k++) {
            double mid = 0.5 * (lo + hi);
            if (value * volume * cubic(mid, h) > iso) lo = mid; else hi = mid;
        }
        const double radius = 0.5 * (lo + hi);
        IsobarAdaptiveParams adaptive;
        CHECK(isobar_adaptive_params_default(&adaptive) == ISOBAR_STATUS_OK, "adaptive defaults");
        CHECK(adaptive.struct_size == sizeof adaptive, "adaptive struct_size");
        IsobarAdaptiveStats astats;
        memset(&astats, 0, sizeof astats);
        astats.struct_size = sizeof astats;
        IsobarSurface *coarse = NULL;
        CHECK(isobar_adaptive_extract(particles, &params, &adaptive, NULL, NULL, &coarse, &astats) == ISOBAR_STATUS_OK,
              "adaptive extract: %s", isobar_last_error_message());
        size_t anv = isobar_surface_vertex_count(coarse), ant = isobar_surface_triangle_count(coarse);
        CHECK(anv > 20 && ant > 40 && astats.triangles == ant && astats.vertices == anv, "adaptive counts");
        const double *axyz = isobar_surface_positions(coarse);
        const double accuracy = params.grid_factor * h / (double)(1u << adaptive.bisection_iterations);
        double off = 0.0;
        for (size_t i = 0; i < anv; i++) {
            double d[3] = {axyz[3 * i] - centre[0], axyz[3 * i + 1] - centre[1], axyz[3 * i + 2] - centre[2]};
            double e = fabs(sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) - radius);
            if (e > off) off = e;
        }
        CHECK(off <= 1.001 * accuracy, "adaptive vertex %g off the sphere (accuracy %g)", off, accuracy);
        isobar_surface_free(coarse);
        /* The error criterion's tolerance (version 3 of the struct): on by default, a
         * negative value refused by name, and a version-2 struct (fields up to `backend`)
         * gets the default whatever lies beyond it: the same surface as the defaults. */
        CHECK(adaptive.max_error > 0.0, "max_error default %g", adaptive.max_error);
        IsobarAdaptiveParams v2 = adaptive;
        v2.max_error = -1.0;
        coarse = NULL;
        CHECK(isobar_adaptive_extract(particles, &params, &v2, NULL, NULL, &coarse, NULL) ==
                  ISOBAR_STATUS_ERR_INVALID_ARGUMENT && coarse == NULL, "max_error < 0 refused");
        CHECK(strstr(isobar_last_error_message(), "max_error") != NULL, "message: %s", isobar_last_error_message());
        v2.struct_size = (uint32_t)offsetof(IsobarAdaptiveParams, max_error);
        CHECK(isobar_adaptive_extract(particles, &params, &v2, NULL, NULL, &coarse, NULL) == ISOBAR_STATUS_OK,
              "version-2 struct: %s", isobar_last_error_message());
        CHECK(isobar_surface_triangle_count(coarse) == ant, "version-2 struct gives the default surface");
        isobar_surface_free(coarse);
        const double two[2] = {iso, 0.5 * iso};
        params.isovalues = two;
        params.isovalue_count = 2;
        coarse = NULL;
        CHECK(isobar_adaptive_extract(particles, &params, &adaptive, NULL, NULL, &coarse, NULL) ==
                  ISOBAR_STATUS_ERR_INVALID_ARGUMENT && coarse == NULL, "adaptive: two isovalues refused");
        CHECK(strstr(isobar_last_error_message(), "one isovalue") != NULL, "message: %s", isobar_last_error_message());
        params.isovalues = &iso;
        params.isovalue_count = 1;
    }

    /* Cancel: the callback's non-zero return stops the work with a distinct status. */
    int cancels = 0;
    surface = NULL;
    CHECK(isobar_sph_extract(particles, &params, cancel_at_once, &cancels, &surface) == ISOBAR_STATUS_CANCELLED, "cancel");
    CHECK(surface == NULL && cancels == 1, "cancelled run leaves no surface");

    /* Bad input: each comes back as a status and a message naming the problem. */
    params.h = -1.0;
    CHECK(isobar_sph_extract(particles, &params, NULL, NULL, &surface) == ISOBAR_STATUS_ERR_INVALID_ARGUMENT, "h < 0");
    CHECK(strstr(isobar_last_error_message(), "smoothing length") != NULL, "message names h");
    params.h = h;
    params.field = "pressure";
    CHECK(isobar_sph_extract(particles, &params, NULL, NULL, &surface) == ISOBAR_STATUS_ERR_INVALID_INPUT, "missing array");
    CHECK(strstr(isobar_last_error_message(), "pressure") != NULL, "message names the array");
    params.field = "a";
    params.struct_size = 3;
    CHECK(isobar_sph_extract(particles, &params, NULL, NULL, &surface) == ISOBAR_STATUS_ERR_INVALID_ARGUMENT, "struct_size");
    params.struct_size = sizeof params;
    CHECK(isobar_sph_extract(NULL, &params, NULL, NULL, &surface) == ISOBAR_STATUS_ERR_INVALID_ARGUMENT, "NULL particles");
    CHECK(isobar_particles_add_array(particles, "short", &value, 5, 1) == ISOBAR_STATUS_ERR_INVALID_ARGUMENT, "length mismatch");
    CHECK(isobar_particles_create(NULL, 10, &particles) == ISOBAR_STATUS_ERR_INVALID_ARGUMENT, "NULL positions");

    const double nan_xyz[6] = {0, 0, 0, 0, NAN, 0};
    IsobarParticles *bad = NULL;
    CHECK(isobar_particles_create(nan_xyz, 2, &bad) == ISOBAR_STATUS_OK, "create nan");
    params.field = NULL;
    params.volume_array = NULL;
    CHECK(isobar_sph_extract(bad, &params, NULL, NULL, &surface) == ISOBAR_STATUS_ERR_INVALID_INPUT, "NaN");
    CHECK(strstr(isobar_last_error_message(), "particle 1") != NULL, "message names particle 1");
    isobar_particles_free(bad);

    IsobarParticles *missing = NULL;
    CHECK(isobar_particles_read("/nonexistent/frame.vtk", &missing) == ISOBAR_STATUS_ERR_IO, "missing file");
    CHECK(strstr(isobar_last_error_message(), "/nonexistent/frame.vtk") != NULL, "message names the file");

    /* High-order FE: one trilinear Lagrange hexahedron over [0, 1]³ (VTK corner order) with
     * f = x; the isosurface f = 0.3 is the plane x = 0.3, every sample on it. */
    {
        const double corners[24] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 0, 0, 1, 1, 0, 1, 1, 1, 1, 0, 1, 1};
        const uint8_t type = 72;
        const int64_t offsets[2] = {0, 8};
        const int64_t conn[8] = {0, 1, 2, 3, 4, 5, 6, 7};
        double f[8];
        for (int i = 0; i < 8; i++) f[i] = corners[3 * i];
        IsobarFeMesh *fe = NULL;
        CHECK(isobar_fe_mesh_create(corners, 8, &type, 1, offsets, conn, 8, NULL, &fe) == ISOBAR_STATUS_OK,
              "fe mesh: %s", isobar_last_error_message());
        CHECK(isobar_fe_mesh_add_array(fe, "f", f, 8, 1) == ISOBAR_STATUS_OK, "fe array");
        IsobarFeParams fp;
        CHECK(isobar_fe_params_default(&fp) == ISOBAR_STATUS_OK && fp.struct_size == sizeof fp, "fe defaults");
        fp.iso = 0.3;
        fp.spacing = 0.1;
        IsobarSamples *samples = NULL;
        CHECK(isobar_fe_sample(fe, "f", &fp, NULL, NULL, &samples) == ISOBAR_STATUS_OK,
              "fe sample: %s", isobar_last_error_message());
        size_t ns = isobar_samples_count(samples);
        const double *sp = isobar_samples_positions(samples);
        const double *sr = isobar_samples_radii(samples);
        CHECK(ns > 30 && sp && sr, "%zu samples", ns);
        double off = 0.0;
        for (size_t i = 0; i < ns; i++) {
            off = fmax(off, fabs(sp[3 * i] - 0.3));
            CHECK(sr[i] > 0.0, "radius %zu", i);
        }
        CHECK(off <= fp.tolerance, "fe sample off the plane by %g", off);
        IsobarFeStats fs;
        fs.struct_size = sizeof fs;
        CHECK(isobar_samples_stats(samples, &fs) == ISOBAR_STATUS_OK && fs.particles == ns, "fe stats");
        CHECK(strcmp(isobar_samples_warnings(samples), "") == 0, "fe warnings: %s", isobar_samples_warnings(samples));
        /* f = x lies in [0, 1]: an isovalue of 2 gives no sample, and says so. */
        IsobarSamples *none = NULL;
        fp.iso = 2.0;
        CHECK(isobar_fe_sample(fe, "f", &fp, NULL, NULL, &none) == ISOBAR_STATUS_OK && isobar_samples_count(none) == 0,
              "fe beyond the field: %s", isobar_last_error_message());
        CHECK(strcmp(isobar_samples_warnings(none), "no surface at isovalue 2: the field never crosses it") == 0,
              "fe warning: '%s'", isobar_samples_warnings(none));
        isobar_samples_free(none);
        /* The mesh's box (widened for rounding), and a spacing of 0 as 1/40 of its
         * diagonal: a host that passes the spacing from the box (as a data-parallel one
         * must) samples alike. */
        double box[6];
        CHECK(isobar_fe_mesh_bounds(fe, box) == ISOBAR_STATUS_OK, "fe bounds: %s", isobar_last_error_message());
        for (int k = 0; k < 3; k++)
            CHECK(box[k] <= 0.0 && box[k] > -1e-6 && box[3 + k] >= 1.0 && box[3 + k] < 1.0 + 1e-6,
                  "fe bounds axis %d: %g %g", k, box[k], box[3 + k]);
        CHECK(isobar_fe_mesh_bounds(NULL, box) == ISOBAR_STATUS_ERR_INVALID_ARGUMENT, "fe bounds NULL mesh");
        CHECK(isobar_fe_mesh_bounds(fe, NULL) == ISOBAR_STATUS_ERR_INVALID_ARGUMENT, "fe bounds NULL out");
        IsobarSamples *by_default = NULL, *by_box = NULL;
        fp.iso = 0.3;
        fp.spacing = 0.0;
        CHECK(isobar_fe_sample(fe, "f", &fp, NULL, NULL, &by_default) == ISOBAR_STATUS_OK, "fe default spacing");
        fp.spacing = sqrt((box[3] - box[0]) * (box[3] - box[0]) + (box[4] - box[1]) * (box[4] - box[1]) +
                          (box[5] - box[2]) * (box[5] - box[2])) / 40.0;
        CHECK(isobar_fe_sample(fe, "f", &fp, NULL, NULL, &by_box) == ISOBAR_STATUS_OK, "fe spacing from the box");
        size_t nd = isobar_samples_count(by_default);
        CHECK(nd > 30 && nd == isobar_samples_count(by_box), "fe samples %zu vs %zu", nd, isobar_samples_count(by_box));
        CHECK(memcmp(isobar_samples_positions(by_default), isobar_samples_positions(by_box), 3 * nd * sizeof(double)) == 0,
              "fe samples from the box's spacing differ");
        isobar_samples_free(by_default);
        isobar_samples_free(by_box);
        fp.spacing = 0.1;
        fp.iso = 0.3;
        CHECK(isobar_fe_sample(fe, "g", &fp, NULL, NULL, &samples) == ISOBAR_STATUS_ERR_INVALID_INPUT, "fe missing field");
        CHECK(strstr(isobar_last_error_message(), "g") != NULL, "message names the field");
        isobar_samples_free(samples);
        isobar_fe_mesh_free(fe);
    }

    /* isobar_fe_probe on a distorted trilinear hexahedron: the unit cube with corner 6 pulled
     * out to (1.4, 1.3, 1.5), so T is not affine and locating a point takes Newton. The
     * field "x" holds each node's x coordinate; an isoparametric cell reproduces it exactly,
     * so the probed value at any inside point is that point's x. The returned reference
     * coordinates are checked by mapping them back with T written out here. */
    {
        const double pts[24] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 0, 0, 1, 1, 0, 1, 1.4, 1.3, 1.5, 0, 1, 1};
        const uint8_t type = 72;
        const int64_t offsets[2] = {0, 8};
        const int64_t conn[8] = {0, 1, 2, 3, 4, 5, 6, 7};
        double fx[8];
        for (int i = 0; i < 8; i++) fx[i] = pts[3 * i];
        IsobarFeMesh *fe = NULL;
        CHECK(isobar_fe_mesh_create(pts, 8, &type, 1, offsets, conn, 8, NULL, &fe) == ISOBAR_STATUS_OK, "probe mesh");
        CHECK(isobar_fe_mesh_add_array(fe, "x", fx, 8, 1) == ISOBAR_STATUS_OK, "probe array");
        /* Four points inside (one near corner 6, where the cell is most distorted), one
         * outside. */
        enum { N = 5 };
        const double at[3 * N] = {0.5, 0.5, 0.5, 0.1, 0.8, 0.3, 0.95, 0.9, 0.97, 1.2, 1.1, 1.25, 3.0, -1.0, 0.5};
        double values[N], reference[3 * N];
        int64_t cells[N];
        CHECK(isobar_fe_probe(fe, "x", at, N, values, cells, reference) == ISOBAR_STATUS_OK, "probe");
        for (int i = 0; i < N - 1; i++) {
            CHECK(cells[i] == 0, "probe point %d: cell %lld", i, (long long)cells[i]);
            CHECK(fabs(values[i] - at[3 * i]) <= 1e-10, "probe point %d: x = %.17g, want %.17g", i, values[i],
                  at[3 * i]);
            const double *u = &reference[3 * i];
            double x[3] = {0, 0, 0};
            for (int c = 0; c < 8; c++) {
                /* VTK corner c sits at (c&1 ^ c>>1&1, c>>1&1, c>>2) on the reference cube. */
                int a = (c & 1) ^ ((c >> 1) & 1), b = (c >> 1) & 1, d = c >> 2;
                double w = (a ? u[0] : 1 - u[0]) * (b ? u[1] : 1 - u[1]) * (d ? u[2] : 1 - u[2]);
                for (int k = 0; k < 3; k++) x[k] += w * pts[3 * c + k];
            }
            for (int k = 0; k < 3; k++)
                CHECK(fabs(x[k] - at[3 * i + k]) <= 1e-10, "probe point %d: T(reference)[%d] = %.17g, want %.17g",
                      i, k, x[k], at[3 * i + k]);
        }
        CHECK(cells[N - 1] == -1 && isnan(values[N - 1]), "outside point: cell %lld, value %g",
              (long long)cells[N - 1], values[N - 1]);
        for (int k = 0; k < 3; k++) CHECK(isnan(reference[3 * (N - 1) + k]), "outside point: reference %d", k);
        /* Cell and reference outputs are optional. */
        double only[N];
        CHECK(isobar_fe_probe(fe, "x", at, N, only, NULL, NULL) == ISOBAR_STATUS_OK, "probe without cells");
        CHECK(memcmp(only, values, sizeof only) == 0, "probe without cells gives other values");
        /* A NaN coordinate is refused, naming its index, before anything is written. */
        double bad[6] = {0.5, 0.5, 0.5, 0.5, NAN, 0.5};
        double untouched[2] = {42.0, 42.0};
        int64_t untouched_cells[2] = {7, 7};
        CHECK(isobar_fe_probe(fe, "x", bad, 2, untouched, untouched_cells, NULL) == ISOBAR_STATUS_ERR_INVALID_ARGUMENT,
              "NaN probe point");
        CHECK(strstr(isobar_last_error_message(), "point 1 ") != NULL, "message names point 1: %s",
              isobar_last_error_message());
        CHECK(untouched[0] == 42.0 && untouched[1] == 42.0 && untouched_cells[0] == 7 && untouched_cells[1] == 7,
              "a refused probe wrote its outputs");
        CHECK(isobar_fe_probe(fe, "nope", at, N, values, NULL, NULL) == ISOBAR_STATUS_ERR_INVALID_INPUT,
              "probe of a missing field");
        CHECK(strstr(isobar_last_error_message(), "nope") != NULL, "message names the field: %s",
              isobar_last_error_message());
        CHECK(isobar_fe_probe(NULL, "x", at, N, values, NULL, NULL) == ISOBAR_STATUS_ERR_INVALID_ARGUMENT,
              "probe of a NULL mesh");
        isobar_fe_mesh_free(fe);
    }

    isobar_particles_free(particles);
    isobar_particles_free(NULL);
    isobar_surface_free(NULL);
    if (failures == 0) printf("capi_test: all checks passed\n");
    return failures == 0 ? 0 : 1;
}
