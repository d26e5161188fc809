// Plain Verilator main for the batch harness of raplas_hdl/sim/build/harness.py: no cocotb, no VPI.
// The limit that the cocotb batch mode is measured against (benchmarks/bench_cosim.py).
// Usage: <exe> +VEC_IN=... +VEC_OUT=... +N_IN=... [+EXT_CLK] [other harness plusargs]
// Without +EXT_CLK the harness makes its own clock (built with --timing); with it this
// main toggles the clk port, the classic Verilator loop.
#include <cstdio>
#include <memory>
#include <string>

#include "Vtop.h"
#include "verilated.h"

int main(int argc, char** argv) {
    auto ctx = std::make_unique<VerilatedContext>();
    ctx->commandArgs(argc, argv);
    const bool ext_clk = !std::string(ctx->commandArgsPlusMatch("EXT_CLK")).empty();
    auto top = std::make_unique<Vtop>(ctx.get());
    unsigned long long cycles = 0;
    top->clk = 0;
    top->rst = 1;
    top->eval();
    if (ext_clk) {
        for (int i = 0; i < 3; ++i) {  // three reset cycles, as the cocotb test does
            top->clk = 1; top->eval();
            top->clk = 0; top->eval();
        }
        top->rst = 0;
        while (!top->done && !ctx->gotFinish()) {
            top->clk = 1; top->eval();
            top->clk = 0; top->eval();
            ++cycles;
        }
    } else {
        while (!top->done && !ctx->gotFinish() && top->eventsPending()) {
            ctx->time(top->nextTimeSlot());
            top->eval();
        }
        cycles = ctx->time() / 10 - 3;  // 10-unit clock period, 3 reset cycles
    }
    top->final();
    std::printf("cycles %llu timeout %d\n", cycles, static_cast<int>(top->timeout));
    return top->timeout ? 1 : 0;
}
