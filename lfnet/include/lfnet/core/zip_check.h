// Integrity of the zip archives LibTorch reads (dictionaries, exported models) before LibTorch
// reads them: its loader trusts what it finds inside, and damaged bytes in an archive's code
// or pickle can crash it instead of raising an error.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace lfnet {

// CRC-32 (IEEE 802.3, the zip checksum) of `size` bytes, continuing from `crc` (0 to start).
uint32_t crc32(const void* data, size_t size, uint32_t crc = 0);

// Checks a zip archive's structure and every entry's CRC-32 against its data: stored entries
// (tensors, pickles) always, deflated ones (TorchScript code) when lfnet was built with zlib
// (LFNET_HAVE_ZLIB). Throws CheckpointError naming `what` (e.g. "dictionary X") and the
// damaged entry. Entries too large for classic zip fields (zip64) are not checked.
void check_zip_integrity(const std::string& path, const std::string& what);

// Whether check_zip_integrity verifies deflated entries (lfnet built with zlib).
bool zip_checks_deflated();

}  // namespace lfnet
