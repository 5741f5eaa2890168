/*
 * insncount — QEMU TCG plugin that counts guest instructions, in total and between two marker
 * functions (see README.md next to this file). Instructions, not cycles.
 *
 *   gcc -O2 -shared -fPIC -fvisibility=hidden -o libinsncount.so insncount.c
 *   qemu-system-arm ... -plugin libinsncount.so,start=0x08000101,end=0x08000105,out=counts.txt
 *
 * start / end: addresses of the first instruction of the start and end marker functions (bit 0,
 * the Thumb bit of a symbol value, is ignored). out: file for the result (default: QEMU's log
 * through qemu_plugin_outs, i.e. stderr when QEMU runs with -d plugin). Argument errors go to
 * stderr and make qemu_plugin_install fail, so QEMU does not start.
 *
 * A region begins when the first instruction of the start marker executes and ends when the
 * first instruction of the end marker executes next; its count is the number of instructions
 * executed from the former (included) to the latter (excluded): the start marker's own body,
 * the measured code, and the call of the end marker. A new start while a region is open restarts
 * it; an end with no open region is ignored; a region still open at exit is dropped.
 *
 * Counting: every executed translation block adds its instruction count to the total (the
 * block callback fires before the block runs). Marker instructions additionally get an
 * instruction callback, which fires only when that instruction really executes; its position
 * in the instruction stream is the total before its block plus its index in the block, so a
 * marker in the middle of a block is placed exactly. (A block left early by a guest fault would
 * still count its unexecuted tail; the bench code does not fault, and a region's end is placed by
 * its marker instruction's own callback either way.) Single vCPU (the counters are not atomic).
 *
 * QEMU distributions (Debian's qemu-system-arm 7.2 among them) do not ship qemu-plugin.h, so the
 * few parts of the plugin API used here are declared below (API version 1, QEMU 7.x).
 */
#include <errno.h>
#include <inttypes.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- QEMU plugin API (subset, as in QEMU 7.2's include/qemu/qemu-plugin.h) ---- */

typedef uint64_t qemu_plugin_id_t;

typedef struct qemu_info_t {
    const char *target_name;
    struct {
        int min;
        int cur;
    } version;
    bool system_emulation;
    union {
        struct {
            int smp_vcpus;
            int max_vcpus;
        } system;
    };
} qemu_info_t;

struct qemu_plugin_tb;
struct qemu_plugin_insn;

enum qemu_plugin_cb_flags {
    QEMU_PLUGIN_CB_NO_REGS,
    QEMU_PLUGIN_CB_R_REGS,
    QEMU_PLUGIN_CB_RW_REGS,
};

typedef void (*qemu_plugin_udata_cb_t)(qemu_plugin_id_t id, void *userdata);
typedef void (*qemu_plugin_vcpu_udata_cb_t)(unsigned int vcpu_index, void *userdata);
typedef void (*qemu_plugin_vcpu_tb_trans_cb_t)(qemu_plugin_id_t id, struct qemu_plugin_tb *tb);

void qemu_plugin_register_vcpu_tb_trans_cb(qemu_plugin_id_t id, qemu_plugin_vcpu_tb_trans_cb_t cb);
void qemu_plugin_register_vcpu_tb_exec_cb(struct qemu_plugin_tb *tb, qemu_plugin_vcpu_udata_cb_t cb,
                                          enum qemu_plugin_cb_flags flags, void *userdata);
void qemu_plugin_register_vcpu_insn_exec_cb(struct qemu_plugin_insn *insn, qemu_plugin_vcpu_udata_cb_t cb,
                                            enum qemu_plugin_cb_flags flags, void *userdata);
void qemu_plugin_register_atexit_cb(qemu_plugin_id_t id, qemu_plugin_udata_cb_t cb, void *userdata);
size_t qemu_plugin_tb_n_insns(const struct qemu_plugin_tb *tb);
struct qemu_plugin_insn *qemu_plugin_tb_get_insn(const struct qemu_plugin_tb *tb, size_t idx);
uint64_t qemu_plugin_insn_vaddr(const struct qemu_plugin_insn *insn);
void qemu_plugin_outs(const char *string);

#define EXPORT __attribute__((visibility("default")))

EXPORT int qemu_plugin_version = 1;

/* ---- state ---- */

static uint64_t start_addr, end_addr; /* bit 0 cleared */
static char *out_path;                /* NULL: qemu_plugin_outs */

static uint64_t total;   /* instructions in all blocks entered so far */
static uint64_t tb_base; /* value of `total` when the current block was entered */

static bool region_open;
static uint64_t region_start; /* stream position of the open region's start marker */
static uint64_t n_regions, sum, min_count, max_count;

/* Marker callback user data: index of the instruction in its block, shifted left by one, with
 * bit 0 set for the end marker. No allocation, so retranslation costs nothing. */
#define MARK_END 1u

/* ---- callbacks ---- */

static void on_tb_exec(unsigned int vcpu_index, void *udata)
{
    (void)vcpu_index;
    tb_base = total;
    total += (uintptr_t)udata;
}

static void on_marker(unsigned int vcpu_index, void *udata)
{
    (void)vcpu_index;
    uintptr_t u = (uintptr_t)udata;
    uint64_t pos = tb_base + (u >> 1);
    if (!(u & MARK_END)) {
        region_open = true;
        region_start = pos;
    } else if (region_open) {
        uint64_t n = pos - region_start;
        region_open = false;
        if (n_regions == 0 || n < min_count) {
            min_count = n;
        }
        if (n_regions == 0 || n > max_count) {
            max_count = n;
        }
        n_regions++;
        sum += n;
    }
}

static void on_tb_trans(qemu_plugin_id_t id, struct qemu_plugin_tb *tb)
{
    (void)id;
    size_t n = qemu_plugin_tb_n_insns(tb);
    qemu_plugin_register_vcpu_tb_exec_cb(tb, on_tb_exec, QEMU_PLUGIN_CB_NO_REGS, (void *)(uintptr_t)n);
    for (size_t i = 0; i < n; i++) {
        struct qemu_plugin_insn *insn = qemu_plugin_tb_get_insn(tb, i);
        uint64_t va = qemu_plugin_insn_vaddr(insn) & ~(uint64_t)1;
        if (va == start_addr || va == end_addr) {
            uintptr_t u = ((uintptr_t)i << 1) | (va == end_addr ? MARK_END : 0);
            qemu_plugin_register_vcpu_insn_exec_cb(insn, on_marker, QEMU_PLUGIN_CB_NO_REGS, (void *)u);
        }
    }
}

static void on_atexit(qemu_plugin_id_t id, void *udata)
{
    (void)id;
    (void)udata;
    /* mean with six decimals, trailing zeros dropped ("8", "141.234"). */
    char mean[64];
    snprintf(mean, sizeof mean, "%.6f", n_regions ? (double)sum / (double)n_regions : 0.0);
    char *p = mean + strlen(mean) - 1;
    while (*p == '0') {
        *p-- = '\0';
    }
    if (*p == '.') {
        *p = '\0';
    }
    char buf[256];
    snprintf(buf, sizeof buf,
             "insncount: total_insns=%" PRIu64 "\n"
             "insncount: regions=%" PRIu64 " mean=%s min=%" PRIu64 " max=%" PRIu64 " sum=%" PRIu64 "\n",
             total, n_regions, mean, n_regions ? min_count : 0, n_regions ? max_count : 0, sum);
    if (out_path) {
        FILE *f = fopen(out_path, "w");
        if (f) {
            fputs(buf, f);
            if (fclose(f) == 0) {
                return;
            }
        }
        fprintf(stderr, "insncount: cannot write %s: %s\n", out_path, strerror(errno));
    }
    qemu_plugin_outs(buf);
}

/* ---- arguments ---- */

__attribute__((format(printf, 1, 2))) static int fail(const char *fmt, ...)
{
    char text[384];
    char msg[640];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    snprintf(msg, sizeof msg,
             "insncount: %s\n"
             "insncount: usage: -plugin libinsncount.so,start=ADDR,end=ADDR[,out=FILE] (ADDR like 0x0800abcd)\n",
             text);
    fputs(msg, stderr); /* not qemu_plugin_outs: QEMU's log is off unless -d plugin */
    return -1;
}

static bool parse_addr(const char *s, uint64_t *out)
{
    if (*s == '\0' || *s == '-' || *s == '+') {
        return false;
    }
    char *end;
    errno = 0;
    unsigned long long v = strtoull(s, &end, 0);
    if (errno != 0 || *end != '\0') {
        return false;
    }
    *out = (uint64_t)v & ~(uint64_t)1;
    return true;
}

static int parse_arg(const char *arg, bool *have_start, bool *have_end)
{
    const char *eq = strchr(arg, '=');
    if (!eq) {
        return fail("argument '%s' is not key=value", arg);
    }
    size_t klen = (size_t)(eq - arg);
    const char *val = eq + 1;
    if (klen == 3 && strncmp(arg, "arg", 3) == 0) { /* legacy form: arg=key=value */
        return parse_arg(val, have_start, have_end);
    }
    if (klen == 5 && strncmp(arg, "start", 5) == 0) {
        if (!parse_addr(val, &start_addr)) {
            return fail("invalid start address '%s' (want hex, e.g. 0x0800abcd)", val);
        }
        *have_start = true;
    } else if (klen == 3 && strncmp(arg, "end", 3) == 0) {
        if (!parse_addr(val, &end_addr)) {
            return fail("invalid end address '%s' (want hex, e.g. 0x0800abcd)", val);
        }
        *have_end = true;
    } else if (klen == 3 && strncmp(arg, "out", 3) == 0) {
        if (*val == '\0') {
            return fail("empty out= file name");
        }
        size_t len = strlen(val) + 1; /* copied: QEMU frees argv after install */
        free(out_path);
        out_path = malloc(len);
        if (!out_path) {
            return fail("out of memory");
        }
        memcpy(out_path, val, len);
    } else {
        return fail("unknown argument '%s' (known: start, end, out)", arg);
    }
    return 0;
}

EXPORT int qemu_plugin_install(qemu_plugin_id_t id, const qemu_info_t *info, int argc, char **argv)
{
    (void)info;
    bool have_start = false, have_end = false;
    for (int i = 0; i < argc; i++) {
        if (parse_arg(argv[i], &have_start, &have_end) != 0) {
            return -1;
        }
    }
    if (!have_start || !have_end) {
        return fail("missing argument%s%s", have_start ? "" : " start=ADDR", have_end ? "" : " end=ADDR");
    }
    if (start_addr == end_addr) {
        return fail("start and end are the same address");
    }
    if (out_path) { /* fail now, not after the whole run, when the file cannot be written */
        FILE *f = fopen(out_path, "w");
        if (!f) {
            return fail("cannot open out file '%s': %s", out_path, strerror(errno));
        }
        fclose(f);
    }
    qemu_plugin_register_vcpu_tb_trans_cb(id, on_tb_trans);
    qemu_plugin_register_atexit_cb(id, on_atexit, NULL);
    return 0;
}
