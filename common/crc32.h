/* crc32: CRC-32 (IEEE 802.3, reflected, poly 0xEDB88320), the same value as zlib's crc32().
 * Used by the .lcb sections and by the lucent/1 binary frames. */
#ifndef LC_CRC32_H
#define LC_CRC32_H
#include <stddef.h>
#include <stdint.h>

/* Continue a CRC: pass 0 to start. lc_crc32(0, "123456789", 9) == 0xCBF43926. */
uint32_t lc_crc32(uint32_t crc, const void *data, size_t len);

#endif
