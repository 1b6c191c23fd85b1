/* Must not compile with liblucent-client's include roots: the client does not link the
 * daemon's state module, so its header is out of reach (tests/CMakeLists.txt). */
#include "state.h"
int main(void) { return 0; }
