"""Stage 1, the emulated boot test: from the reset vector to every task's first await.

Checks, in order: the reset handler writes only .bss, .data and the stack; `main` is reached;
the clock tree is the one clocks.rs asks for (and was switched in RM0433's order); every
embassy task pool holds a spawned task that has been polled and now waits (the executor idles
in WFE with no interrupt pending); no unmapped or unmodelled address was touched, no fault, no
spin on a register. Reports the stack high-water mark.
"""

from unicorn import UC_HOOK_CODE
from unicorn.arm_const import UC_ARM_REG_R0

from .rcc import check_clock_tree

BOOT_LIMIT_NS = 2e9  # emulated time the boot may take before it counts as stuck
# Bytes of a task's header searched for its poll function pointer (embassy's TaskHeader is
# not repr(C): its field order is the compiler's, so the pointer is looked for, not read).
HEADER_SCAN = 64
# embassy's per-task poll functions (one monomorph per task, entered with the task in r0).
POLL_FN = "embassy_executor::raw::TaskStorage<F>::poll"


class TaskWatch:
    """Counts the executor's polls of each embassy task: every `TaskStorage<F>::poll`
    monomorph is entered with the task's header (= its POOL static) in r0. After the first
    idle, a task that has been polled and whose header does not point at `poll_exited` is
    waiting at an await; one that points there has returned."""

    def __init__(self, machine):
        self.machine = machine
        self.pools = {addr: name.replace("touchdown_firmware::", "")
                      for name, addr in machine.elf.pools().items()}
        self.polls = dict.fromkeys(self.pools, 0)
        self.hooks = [
            machine.uc.hook_add(UC_HOOK_CODE, self._on_poll, begin=addr, end=addr)
            for addr in machine.elf.function_addresses(POLL_FN)
        ]

    def detach(self):
        """Removes the hooks (they slow every instruction of a counted run)."""
        for hook in self.hooks:
            self.machine.uc.hook_del(hook)
        self.hooks = []

    def _on_poll(self, uc, addr, size, _ud):
        task = uc.reg_read(UC_ARM_REG_R0)
        if task in self.polls:
            self.polls[task] += 1

    def states(self):
        """(name, polls, returned) per task pool."""
        exited = self.machine.elf.function_addresses("embassy_executor::raw::poll_exited")
        out = []
        for addr, name in sorted(self.pools.items()):
            header = self.machine.uc.mem_read(addr, HEADER_SCAN)
            words = {int.from_bytes(header[i:i + 4], "little") & ~1
                     for i in range(0, HEADER_SCAN, 4)}
            out.append((name, self.polls[addr], bool(words & set(exited))))
        return out


def run_boot(machine, board, args):
    """Runs from reset to the first idle and checks it; prints the boot part of the summary,
    returns the problems found."""
    tasks = TaskWatch(machine)
    machine.run(BOOT_LIMIT_NS, machine.reset())
    tasks.detach()
    problems = []
    if machine.failure:
        problems.append(machine.failure)
    elif machine.finished is None:
        problems.append(f"did not reach an idle executor within {BOOT_LIMIT_NS / 1e9:g} s "
                        f"of emulated time ({machine.elf.where(machine.pc())})")
    if machine.main_at is None:
        problems.append("main never reached")
    else:
        print(f"  reached main at instruction {machine.main_at}")
    if machine.main_at is None or machine.failure:
        return problems
    clock_problems, summary = check_clock_tree(
        machine.rcc, machine.pwr, machine.flash, machine.syscfg,
        board.expected_clocks(args.cpu_mhz))
    print(f"  clock tree {'OK' if not clock_problems else 'WRONG'}: {summary}")
    writes = sum(len(b.log) for b in (machine.rcc, machine.pwr, machine.flash, machine.syscfg))
    print(f"  {writes} RCC/PWR/FLASH/SYSCFG writes; the chip ignores part of "
          f"{len(machine.rcc.ignored)} (PLL fields written while that PLL runs)"
          + "".join(f"\n    RCC.{machine.rcc.names.get(off, hex(off))} = {value:#010x} at "
                    f"{machine.elf.where(pc)}" for pc, off, value in machine.rcc.ignored))
    problems += [f"clock tree: {p}" for p in clock_problems]
    states = tasks.states()
    if not states:
        problems.append("no embassy task pools (::POOL symbols) in the ELF")
    for name, polls, returned in states:
        state = "returned" if returned else "waiting at an await" if polls else "never polled"
        print(f"  task {name}: polled {polls}x, {state}")
        if not polls or (returned and name != "__embassy_main"):
            problems.append(f"task {name}: {state}")
    print(f"  first idle after ~{machine.instructions} instructions, "
          f"{machine.time_ns / 1e6:.3f} ms emulated")
    return problems


def report_stack(machine):
    """Prints the stack high-water mark; returns the problems (a stack that used all of its
    room, or more than memory.x reserves for it)."""
    used = machine.stack_high_water()
    room = machine.stack_start - machine.stack_end
    reserve = machine.elf.symbols.get("__stack_reserve")
    print(f"  stack high-water {used} bytes ({room} bytes of DTCM free for the stack"
          + (f", memory.x reserves {reserve}: {100 * used / reserve:.0f} % of it)"
             if reserve else ")"))
    if used >= room:
        return ["the stack used all of its room (or the paint was overwritten)"]
    # The reserve is what memory.x promises the stack (a link-time check keeps that much DTCM
    # free); a run that needs more would overflow once `.bss` grows into the slack.
    if reserve and used > reserve:
        return [f"stack high-water {used} bytes is over memory.x's __stack_reserve {reserve}"]
    return []
