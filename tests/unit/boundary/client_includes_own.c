/* The control: with the same command, the client's own header and what it links compile. */
#include "lucent_client.h"
#include "lucent_proto.h"
#include "util/half.h"
int main(void) { return 0; }
