/*
 * m7prof: QEMU TCG plugin (API v1, QEMU 7.2) that counts executed guest instructions per
 * address, between the same two marker functions as m7count, and writes one file per
 * region: `<dir>/region-<k>.txt`, a line "<hex address> <count>" per executed address.
 * scripts/m7_profile.sh builds it, runs the Cortex-M7 benchmark under it and sums the counts
 * per function.
 *
 * Why not m7count's mnemonic histogram: the question in speed work is *where* the
 * instructions of a frame go (which function, which loop), and only addresses answer it.
 *
 * Arguments: start=<addr>,stop=<addr>,dir=<directory>. Addresses below 4 MiB (the AN500's
 * flash, where the benchmark's code lives) are counted; others are ignored.
 */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <qemu-plugin.h>

QEMU_PLUGIN_EXPORT int qemu_plugin_version = QEMU_PLUGIN_VERSION;

/* Thumb instructions are halfword aligned: one counter per halfword of 4 MiB. */
#define CODE_BYTES (4u << 20)
#define SLOTS (CODE_BYTES / 2)

static uint64_t *counts;   /* incremented inline by the generated code */
static uint64_t *at_start; /* counts when the current region opened */
static uint64_t start_addr = UINT64_MAX, stop_addr = UINT64_MAX;
static uint64_t region_no;
static char out_dir[512] = ".";

static void on_start(unsigned int vcpu, void *udata)
{
    (void)vcpu; (void)udata;
    memcpy(at_start, counts, sizeof(uint64_t) * SLOTS);
}

static void on_stop(unsigned int vcpu, void *udata)
{
    char path[600];
    (void)vcpu; (void)udata;
    snprintf(path, sizeof path, "%s/region-%" PRIu64 ".txt", out_dir, region_no++);
    FILE *f = fopen(path, "w");
    if (!f) {
        qemu_plugin_outs("m7prof: cannot write a region file\n");
        return;
    }
    for (uint32_t i = 0; i < SLOTS; i++) {
        uint64_t n = counts[i] - at_start[i];
        if (n) {
            fprintf(f, "%" PRIx32 " %" PRIu64 "\n", i * 2, n);
        }
    }
    fclose(f);
}

static void tb_trans(qemu_plugin_id_t id, struct qemu_plugin_tb *tb)
{
    (void)id;
    size_t n = qemu_plugin_tb_n_insns(tb);
    for (size_t i = 0; i < n; i++) {
        struct qemu_plugin_insn *insn = qemu_plugin_tb_get_insn(tb, i);
        uint64_t va = qemu_plugin_insn_vaddr(insn);
        /* The marker callbacks first, so a region counts from its start marker's first
         * instruction up to (not including) the stop marker's, as m7count does. */
        if (va == start_addr) {
            qemu_plugin_register_vcpu_insn_exec_cb(insn, on_start, QEMU_PLUGIN_CB_NO_REGS, NULL);
        }
        if (va == stop_addr) {
            qemu_plugin_register_vcpu_insn_exec_cb(insn, on_stop, QEMU_PLUGIN_CB_NO_REGS, NULL);
        }
        if (va < CODE_BYTES) {
            qemu_plugin_register_vcpu_insn_exec_inline(insn, QEMU_PLUGIN_INLINE_ADD_U64,
                                                       &counts[va / 2], 1);
        }
    }
}

QEMU_PLUGIN_EXPORT int qemu_plugin_install(qemu_plugin_id_t id, const qemu_info_t *info,
                                           int argc, char **argv)
{
    (void)info;
    for (int i = 0; i < argc; i++) {
        if (!strncmp(argv[i], "start=", 6)) {
            start_addr = strtoull(argv[i] + 6, NULL, 0) & ~1ull;
        } else if (!strncmp(argv[i], "stop=", 5)) {
            stop_addr = strtoull(argv[i] + 5, NULL, 0) & ~1ull;
        } else if (!strncmp(argv[i], "dir=", 4)) {
            snprintf(out_dir, sizeof out_dir, "%s", argv[i] + 4);
        } else {
            fprintf(stderr, "m7prof: unknown argument %s\n", argv[i]);
            return -1;
        }
    }
    counts = calloc(SLOTS, sizeof(uint64_t));
    at_start = calloc(SLOTS, sizeof(uint64_t));
    if (!counts || !at_start) {
        return -1;
    }
    qemu_plugin_register_vcpu_tb_trans_cb(id, tb_trans);
    return 0;
}
