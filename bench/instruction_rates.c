/* How fast this CPU runs the instructions the AVX2 kernels are made of: each case a loop of
 * eight instructions independent within an iteration (or a kernel's pattern), timed for 10^8
 * iterations. Each register is written once an iteration, so an instruction's latency bounds its
 * loop too (a multiply-add's four cycles on the Zen 3 equal eight at two a cycle). Cycles are at
 * the clock the first case measures (eight dependent integer adds take eight cycles).
 * docs/performance.md ("On an AMD Zen 3") reads them. Build and run (x86-64, gcc or clang):
 *
 *     gcc -O1 bench/instruction_rates.c -o target/instruction_rates && target/instruction_rates
 */
#include <stdio.h>
#include <time.h>

static float buf[1024] __attribute__((aligned(64)));

static double now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + t.tv_nsec * 1e-9;
}

#define LOOPS 100000000L
#define ZERO(r) "vxorps %%ymm" #r ",%%ymm" #r ",%%ymm" #r "\n"
/* Times `body` (which may use ymm0-15, rax and the buffer in %1); prints ns and cycles a loop. */
#define CASE(name, body)                                                                          \
    {                                                                                             \
        long n = LOOPS;                                                                           \
        double t0 = now();                                                                        \
        __asm__ volatile(ZERO(0) ZERO(1) ZERO(2) ZERO(3) ZERO(4) ZERO(5) ZERO(6) ZERO(7) ZERO(8)   \
                             ZERO(9) ZERO(10) ZERO(11) ZERO(12) ZERO(13) ZERO(14) ZERO(15)        \
                         "1:\n" body "\ndec %0\njnz 1b"                                           \
                         : "+r"(n)                                                                \
                         : "r"(buf)                                                               \
                         : "memory", "rax", "xmm0", "xmm1", "xmm2", "xmm3", "xmm4", "xmm5", "xmm6", \
                           "xmm7", "xmm8", "xmm9", "xmm10", "xmm11", "xmm12", "xmm13", "xmm14",   \
                           "xmm15");                                                              \
        double ns = (now() - t0) / LOOPS * 1e9;                                                   \
        ghz = ghz_of(name, ns, ghz);                                                              \
        printf("%-58s %6.2f ns  %6.2f cycles\n", name, ns, ns * ghz);                             \
    }

/* The first case calibrates the clock: eight dependent adds are eight cycles. */
static double ghz_of(const char *name, double ns, double ghz) {
    return name[0] == '=' ? 8.0 / ns : ghz;
}

#define EIGHT(op) op(0) op(1) op(2) op(3) op(4) op(5) op(6) op(7)
#define ADD(k) "add $1,%%rax\n"
#define FMA_REG(k) "vfmadd231ps %%ymm14,%%ymm15,%%ymm" #k "\n"
#define FMA_MEM(k) "vfmadd231ps " #k "*32(%1),%%ymm15,%%ymm" #k "\n"
#define LOAD(k) "vmovups " #k "*32(%1),%%ymm" #k "\n"
#define BCAST(k) "vbroadcastss " #k "*4(%1),%%ymm" #k "\n"
#define PERMPS(k) "vpermps %%ymm14,%%ymm15,%%ymm" #k "\n"
#define PERMPS_MEM(k) "vpermps " #k "*32(%1),%%ymm15,%%ymm" #k "\n"
#define PERMILPS(k) "vpermilps %%ymm14,%%ymm15,%%ymm" #k "\n"
#define PERM2F128(k) "vperm2f128 $0x31,%%ymm14,%%ymm15,%%ymm" #k "\n"
#define INSERT_MEM(k) "vinsertf128 $1," #k "*16(%1),%%ymm15,%%ymm" #k "\n"
#define BCAST128(k) "vbroadcastf128 " #k "*16(%1),%%ymm" #k "\n"
#define LOAD128(k) "vmovups " #k "*16(%1),%%xmm" #k "\n"
/* One lane pair's two records (lanes l and l + 4) in one register, as the AVX2 kernels gather
 * rotations: a 128-bit load and an insert from memory, or a load, a broadcast and a blend. */
#define PAIR_INSERT(k) "vmovups " #k "*32(%1),%%xmm" #k "\n" \
                       "vinsertf128 $1,16+" #k "*32(%1),%%ymm" #k ",%%ymm" #k "\n"
#define PAIR_BLEND(k) "vmovups " #k "*32(%1),%%xmm" #k "\n"       \
                      "vbroadcastf128 16+" #k "*32(%1),%%ymm1" #k "\n" \
                      "vblendps $0xf0,%%ymm1" #k ",%%ymm" #k ",%%ymm" #k "\n"
/* A gather of eight floats by eight indices (all 0 here: the cache's best case), its mask set
 * again first (the gather clears it). Four a loop, each with its own mask register. */
#define GATHER(k, m) "vpcmpeqd %%ymm" #m ",%%ymm" #m ",%%ymm" #m "\n" \
                     "vgatherdps %%ymm" #m ",(%1,%%ymm9,4),%%ymm" #k "\n"
#define DPPS(k) "vdpps $0xff,%%ymm14,%%ymm15,%%ymm" #k "\n"
#define UNPCK(k) "vunpcklps %%ymm14,%%ymm15,%%ymm" #k "\n"
#define BLEND(k) "vblendps $0xf0,%%ymm14,%%ymm15,%%ymm" #k "\n"
/* The LBS sums' pattern for one lane (`avx2.rs`, `window_sums`): its weight broadcast, then the
 * two halves of its bone's record times it, into two accumulators. */
#define LANE(k, a, b) "vbroadcastss " #k "*4(%1),%%ymm" #a "\n"                     \
                      "vfmadd231ps 64+" #k "*64(%1),%%ymm" #a ",%%ymm" #k "\n"       \
                      "vfmadd231ps 96+" #k "*64(%1),%%ymm" #a ",%%ymm" #b "\n"
#define LANE_NO_WEIGHT(k, a, b) "vfmadd231ps 64+" #k "*64(%1),%%ymm" #a ",%%ymm" #k "\n" \
                                "vfmadd231ps 96+" #k "*64(%1),%%ymm" #a ",%%ymm" #b "\n"

/* The same with the four lanes' weights loaded once into both halves of a register and spread
 * by in-lane shuffles (`vpermilps` with an immediate). */
#define LANE_SHUFFLED(k, a, b, imm) "vpermilps $" #imm ",%%ymm12,%%ymm" #a "\n"                   \
                                    "vfmadd231ps 64+" #k "*64(%1),%%ymm" #a ",%%ymm" #k "\n" \
                                    "vfmadd231ps 96+" #k "*64(%1),%%ymm" #a ",%%ymm" #b "\n"

int main(void) {
    double ghz = 1.0;
    CASE("= eight dependent integer adds (the clock)", EIGHT(ADD));
    printf("clock: %.2f GHz\n", ghz);
    CASE("eight FMAs, registers", EIGHT(FMA_REG));
    CASE("eight FMAs, one operand from memory", EIGHT(FMA_MEM));
    CASE("eight 256-bit loads", EIGHT(LOAD));
    CASE("eight broadcasts from memory", EIGHT(BCAST));
    CASE("eight vpermps", EIGHT(PERMPS));
    CASE("eight vpermps from memory", EIGHT(PERMPS_MEM));
    CASE("eight vpermilps", EIGHT(PERMILPS));
    CASE("eight vperm2f128", EIGHT(PERM2F128));
    CASE("eight vinsertf128 from memory", EIGHT(INSERT_MEM));
    CASE("eight vbroadcastf128 from memory", EIGHT(BCAST128));
    CASE("eight 128-bit loads", EIGHT(LOAD128));
    CASE("eight lane pairs: a load and vinsertf128 from memory", EIGHT(PAIR_INSERT));
    CASE("six lane pairs: a load, vbroadcastf128 and vblendps",
         PAIR_BLEND(0) PAIR_BLEND(1) PAIR_BLEND(2) PAIR_BLEND(3) PAIR_BLEND(4) PAIR_BLEND(5));
    CASE("four vgatherdps (eight floats each)", GATHER(0, 10) GATHER(1, 11) GATHER(2, 12) GATHER(3, 13));
    CASE("eight vdpps (a dot product in each half)", EIGHT(DPPS));
    CASE("eight vunpcklps", EIGHT(UNPCK));
    CASE("eight vblendps", EIGHT(BLEND));
    CASE("LBS sums, four lanes (a broadcast, two FMAs from memory)",
         LANE(0, 8, 4) LANE(1, 9, 5) LANE(2, 10, 6) LANE(3, 11, 7));
    CASE("the same without the broadcasts",
         LANE_NO_WEIGHT(0, 8, 4) LANE_NO_WEIGHT(1, 9, 5) LANE_NO_WEIGHT(2, 10, 6) LANE_NO_WEIGHT(3, 11, 7));
    CASE("the same, the weights shuffled from one 128-bit broadcast",
         "vbroadcastf128 (%1),%%ymm12\n" LANE_SHUFFLED(0, 8, 4, 0x00) LANE_SHUFFLED(1, 9, 5, 0x55)
             LANE_SHUFFLED(2, 10, 6, 0xaa) LANE_SHUFFLED(3, 11, 7, 0xff));
    return 0;
}
