/* A loop in native code that never returns and no signal handler interrupts (a Python
 * controller stuck in a solver): tests/cosim/sleepy.py NativePI. */
void hostile_spin(void);

void hostile_spin(void) {
    volatile unsigned long spin = 0;
    for (;;) spin++;
}
