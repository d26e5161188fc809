// Verilator main of the simulated board (raplas_hdl/sim/drive/serial_board_sim.py): the
// serial board design (raplas_hdl/rtl/serial_board.py) clocked here, its UART pins driven
// bit by bit from a pseudo-terminal, so that a host opens the terminal's name as it would a
// board's serial port (raplas_hdl/link/serial_bus.py, or LiteX's litex_server --uart).
//
// Usage: <exe> +PTY_NAME=FILE +DIVISOR=N [+RESET=N]
//   FILE receives the terminal's name (written once the terminal is ready);
//   N is the design's clocks per bit (its UART divisor).
// The simulation runs until its standard input closes (the launcher's pipe; the launcher
// going away closes it too). Every byte the host writes becomes one 8N1 frame on rx,
// frames back to back; every frame on tx is decoded in the middle of its bits and written
// back. Python is not in the clock loop: the terminal is read every 64 clocks while rx is
// idle, and written as bytes complete. After 2^20 clocks without a byte either way the host
// is taken to be away: the simulation then waits on the terminal for up to 5 ms between
// runs of 256 clocks (the board's state is kept; a byte resumes full speed at once), so an
// idle simulated board costs next to no CPU.
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fcntl.h>
#include <memory>
#include <poll.h>
#include <string>
#include <termios.h>
#include <unistd.h>

#include "Vtop.h"
#include "verilated.h"

static long plusarg_long(VerilatedContext* ctx, const char* name, long dflt) {
    std::string key = std::string(name) + "=";
    const char* m = ctx->commandArgsPlusMatch(key.c_str());
    if (!m || !*m) return dflt;
    return std::strtol(m + 1 + key.size(), nullptr, 10);
}

static std::string plusarg_str(VerilatedContext* ctx, const char* name) {
    std::string key = std::string(name) + "=";
    const char* m = ctx->commandArgsPlusMatch(key.c_str());
    if (!m || !*m) return "";
    return std::string(m + 1 + key.size());
}

int main(int argc, char** argv) {
    auto ctx = std::make_unique<VerilatedContext>();
    ctx->commandArgs(argc, argv);
    const long divisor = plusarg_long(ctx.get(), "DIVISOR", 0);
    const long reset_clocks = plusarg_long(ctx.get(), "RESET", 8);
    const std::string name_file = plusarg_str(ctx.get(), "PTY_NAME");
    if (divisor < 4 || name_file.empty()) {
        std::fprintf(stderr, "usage: %s +PTY_NAME=FILE +DIVISOR=N (N >= 4)\n", argv[0]);
        return 2;
    }

    int master = posix_openpt(O_RDWR | O_NOCTTY);
    if (master < 0 || grantpt(master) != 0 || unlockpt(master) != 0) {
        std::perror("pseudo-terminal");
        return 2;
    }
    const char* slave_name = ptsname(master);
    // hold the slave end open in raw mode: the host's opens and closes then neither hang up
    // the terminal nor see cooked-mode processing of the board's bytes
    int slave = open(slave_name, O_RDWR | O_NOCTTY);
    struct termios tio;
    if (slave < 0 || tcgetattr(slave, &tio) != 0) {
        std::perror("pseudo-terminal slave");
        return 2;
    }
    cfmakeraw(&tio);
    tcsetattr(slave, TCSANOW, &tio);
    fcntl(master, F_SETFL, fcntl(master, F_GETFL) | O_NONBLOCK);
    {
        std::string tmp = name_file + ".tmp";
        FILE* f = std::fopen(tmp.c_str(), "w");
        if (!f) { std::perror("PTY_NAME"); return 2; }
        std::fprintf(f, "%s\n", slave_name);
        std::fclose(f);
        std::rename(tmp.c_str(), name_file.c_str());
    }

    auto top = std::make_unique<Vtop>(ctx.get());
    top->clk = 0;
    top->rst = 1;
    top->rx = 1;
    top->eval();
    for (long i = 0; i < reset_clocks; ++i) {
        top->clk = 1; top->eval();
        top->clk = 0; top->eval();
    }
    top->rst = 0;

    unsigned char in_buf[4096];
    long in_len = 0, in_pos = 0;
    int rx_bit = -1;            // -1 idle, 0 start bit, 1..8 data bits, 9 stop bit
    long rx_left = 0;           // clocks left in the current bit
    unsigned rx_byte = 0;
    int tx_phase = -1;          // -1 idle, 0 start bit (to its middle), 1..8 data, 9 stop
    long tx_left = 0;
    unsigned tx_byte = 0;
    std::string out_buf;
    unsigned long long cycles = 0, bytes_in = 0, bytes_out = 0, quiet = 0;
    const unsigned long long idle_after = 1ull << 20;
    struct pollfd stdin_poll = {0, POLLIN, 0};
    struct pollfd master_poll = {master, POLLIN, 0};

    for (;;) {
        if (rx_bit < 0) {
            if (in_pos == in_len && tx_phase < 0 && out_buf.empty() && quiet > idle_after &&
                (cycles & 255) == 0)
                poll(&master_poll, 1, 5);            // the host is away: wait for a byte
            if (in_pos == in_len && (cycles & 63) == 0) {
                ssize_t n = read(master, in_buf, sizeof in_buf);
                if (n > 0) { in_len = n; in_pos = 0; }
            }
            if (in_pos < in_len) {
                rx_byte = in_buf[in_pos++];
                rx_bit = 0;
                rx_left = divisor;
                ++bytes_in;
            }
        }
        top->rx = rx_bit < 0 ? 1 : rx_bit == 0 ? 0 : rx_bit <= 8 ? (rx_byte >> (rx_bit - 1)) & 1 : 1;
        top->clk = 1; top->eval();
        top->clk = 0; top->eval();
        ++cycles;
        ++quiet;
        if (rx_bit >= 0 || tx_phase >= 0) quiet = 0;
        if (rx_bit >= 0 && --rx_left == 0) {
            rx_left = divisor;
            if (++rx_bit > 9) rx_bit = -1;
        }
        // tx: find a start bit's falling edge, then sample each bit in its middle
        if (tx_phase < 0) {
            if (!top->tx) { tx_phase = 0; tx_left = divisor / 2; tx_byte = 0; }
        } else if (--tx_left == 0) {
            if (tx_phase == 0) {
                if (top->tx) tx_phase = -1;          // a glitch, not a start bit
                else { tx_phase = 1; tx_left = divisor; }
            } else if (tx_phase <= 8) {
                tx_byte |= (top->tx & 1u) << (tx_phase - 1);
                ++tx_phase;
                tx_left = divisor;
            } else {                                 // the stop bit's middle
                out_buf.push_back(static_cast<char>(tx_byte));
                ++bytes_out;
                tx_phase = -1;
            }
        }
        if (!out_buf.empty()) {
            ssize_t n = write(master, out_buf.data(), out_buf.size());
            if (n > 0) out_buf.erase(0, static_cast<size_t>(n));
        }
        if ((cycles & 4095) == 0) {
            if (poll(&stdin_poll, 1, 0) > 0) {
                char c;
                if ((stdin_poll.revents & (POLLHUP | POLLERR)) || read(0, &c, 1) <= 0) break;
            }
            if (ctx->gotFinish()) break;
        }
    }
    top->final();
    std::printf("cycles %llu bytes_in %llu bytes_out %llu\n", cycles, bytes_in, bytes_out);
    close(slave);
    close(master);
    return 0;
}
