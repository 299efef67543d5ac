/*
 * umbra_icount: a QEMU TCG plugin (API v1) that counts the guest instructions executed between
 * two marker addresses, once per marker pair, and writes one line per window:
 *
 *     window <index> insns <count>
 *
 * Arguments (-plugin path/libumbra_icount.so,begin=0xADDR,end=0xADDR,out=FILE):
 *   begin, end  addresses of the first instruction of the two marker functions (Thumb bit clear)
 *   out         file the lines are written to (flushed per line)
 *   profile     optional file: at exit, "<block address> <instructions>" for every translated
 *               block, counting only executions inside windows (for finding hot code; slower)
 *
 * Counting: every translated block adds its instruction count to a 64-bit counter when it starts
 * executing (an inline add, no callback). The marker instructions snapshot the counter. Under
 * -icount shift=0 QEMU never starts a block it cannot finish (it retranslates a shorter one), and
 * the firmware takes no interrupts inside a window, so the count is exact and repeatable: it is
 * the number of instructions from the begin marker's block to the end marker's block, a fixed
 * offset of a few instructions from the code between the calls (the markers' own bodies).
 */
#ifdef UMBRA_USE_SYSTEM_QEMU_PLUGIN_H
#include <qemu-plugin.h>
#else
#include "qemu-plugin-v1.h"
#endif

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

QEMU_PLUGIN_EXPORT int qemu_plugin_version = 1;

static uint64_t executed;      /* instructions of every block started so far */
static uint64_t window_start;  /* counter at the last begin marker */
static uint64_t begin_addr, end_addr;
static uint64_t windows;       /* completed windows */
static int in_window;
static FILE *out;
static FILE *profile;

/* Profile records: one per translated block (retranslations get their own record). */
struct tb_record {
    uint64_t vaddr;
    uint64_t n;
    uint64_t insns;
    struct tb_record *next;
};
static struct tb_record *records;

static void on_tb_exec(unsigned int vcpu, void *udata)
{
    (void)vcpu;
    struct tb_record *r = udata;
    if (in_window) {
        r->insns += r->n;
    }
}

static void on_begin(unsigned int vcpu, void *udata)
{
    (void)vcpu;
    (void)udata;
    window_start = executed;
    in_window = 1;
}

static void on_end(unsigned int vcpu, void *udata)
{
    (void)vcpu;
    (void)udata;
    if (!in_window) {
        return;
    }
    in_window = 0;
    fprintf(out, "window %" PRIu64 " insns %" PRIu64 "\n", windows, executed - window_start);
    fflush(out);
    windows++;
}

static void on_tb_trans(qemu_plugin_id_t id, struct qemu_plugin_tb *tb)
{
    (void)id;
    size_t n = qemu_plugin_tb_n_insns(tb);
    qemu_plugin_register_vcpu_tb_exec_inline(tb, QEMU_PLUGIN_INLINE_ADD_U64, &executed, n);
    if (profile && n > 0) {
        struct tb_record *r = calloc(1, sizeof *r);
        if (r) {
            r->vaddr = qemu_plugin_insn_vaddr(qemu_plugin_tb_get_insn(tb, 0));
            r->n = n;
            r->next = records;
            records = r;
            qemu_plugin_register_vcpu_tb_exec_cb(tb, on_tb_exec, QEMU_PLUGIN_CB_NO_REGS, r);
        }
    }
    for (size_t i = 0; i < n; i++) {
        struct qemu_plugin_insn *insn = qemu_plugin_tb_get_insn(tb, i);
        uint64_t va = qemu_plugin_insn_vaddr(insn);
        if (va == begin_addr) {
            qemu_plugin_register_vcpu_insn_exec_cb(insn, on_begin, QEMU_PLUGIN_CB_NO_REGS, NULL);
        } else if (va == end_addr) {
            qemu_plugin_register_vcpu_insn_exec_cb(insn, on_end, QEMU_PLUGIN_CB_NO_REGS, NULL);
        }
    }
}

static void on_plugin_exit(qemu_plugin_id_t id, void *udata)
{
    (void)id;
    (void)udata;
    fprintf(out, "total insns %" PRIu64 " windows %" PRIu64 "\n", executed, windows);
    fflush(out);
    if (out != stderr) {
        fclose(out);
    }
    if (profile) {
        for (struct tb_record *r = records; r; r = r->next) {
            if (r->insns) {
                fprintf(profile, "%#" PRIx64 " %" PRIu64 "\n", r->vaddr, r->insns);
            }
        }
        fclose(profile);
    }
}

static int parse_u64(const char *s, uint64_t *v)
{
    char *end = NULL;
    unsigned long long x = strtoull(s, &end, 0);
    if (end == s || *end != '\0') {
        return -1;
    }
    *v = (uint64_t)x;
    return 0;
}

QEMU_PLUGIN_EXPORT int qemu_plugin_install(qemu_plugin_id_t id, const qemu_info_t *info, int argc,
                                           char **argv)
{
    (void)info;
    const char *path = NULL;
    int have_begin = 0, have_end = 0;
    for (int i = 0; i < argc; i++) {
        const char *a = argv[i];
        if (strncmp(a, "begin=", 6) == 0 && parse_u64(a + 6, &begin_addr) == 0) {
            have_begin = 1;
        } else if (strncmp(a, "end=", 4) == 0 && parse_u64(a + 4, &end_addr) == 0) {
            have_end = 1;
        } else if (strncmp(a, "out=", 4) == 0) {
            path = a + 4;
        } else if (strncmp(a, "profile=", 8) == 0) {
            profile = fopen(a + 8, "w");
            if (!profile) {
                fprintf(stderr, "umbra_icount: cannot open '%s'\n", a + 8);
                return -1;
            }
        } else {
            fprintf(stderr, "umbra_icount: unknown or malformed argument '%s'\n", a);
            return -1;
        }
    }
    if (!have_begin || !have_end || begin_addr == end_addr) {
        fprintf(stderr, "umbra_icount: need distinct begin=ADDR and end=ADDR\n");
        return -1;
    }
    begin_addr &= ~(uint64_t)1;
    end_addr &= ~(uint64_t)1;
    out = path ? fopen(path, "w") : stderr;
    if (!out) {
        fprintf(stderr, "umbra_icount: cannot open '%s'\n", path);
        return -1;
    }
    qemu_plugin_register_vcpu_tb_trans_cb(id, on_tb_trans);
    qemu_plugin_register_atexit_cb(id, on_plugin_exit, NULL);
    return 0;
}
