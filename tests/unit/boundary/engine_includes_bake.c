/* Must not compile with the engine's include roots: the relight engine does not link the
 * offline bake (tools/bake), so a bake header is out of reach. */
#include "bake/links.h"
int main(void) { return 0; }
