#include "lfnet/core/zip_check.h"

#include <array>
#include <fstream>
#include <iterator>
#include <vector>

#include "lfnet/core/error.h"

#ifdef LFNET_HAVE_ZLIB
#include <zlib.h>
#endif

namespace lfnet {

namespace {

const std::array<uint32_t, 256>& crc_table() {
  static const std::array<uint32_t, 256> table = [] {
    std::array<uint32_t, 256> t{};
    for (uint32_t i = 0; i < 256; ++i) {
      uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[i] = c;
    }
    return t;
  }();
  return table;
}

uint32_t u32(const std::string& b, size_t at) {
  return static_cast<uint32_t>(static_cast<uint8_t>(b[at])) |
         static_cast<uint32_t>(static_cast<uint8_t>(b[at + 1])) << 8 |
         static_cast<uint32_t>(static_cast<uint8_t>(b[at + 2])) << 16 |
         static_cast<uint32_t>(static_cast<uint8_t>(b[at + 3])) << 24;
}

uint16_t u16(const std::string& b, size_t at) {
  return static_cast<uint16_t>(static_cast<uint8_t>(b[at]) | static_cast<uint8_t>(b[at + 1]) << 8);
}

constexpr uint32_t kLocalHeader = 0x04034b50, kCentralHeader = 0x02014b50,
                   kEndOfCentral = 0x06054b50;
constexpr uint32_t kZip64 = 0xFFFFFFFFu;
constexpr uint16_t kStored = 0, kDeflated = 8;

#ifdef LFNET_HAVE_ZLIB
// The CRC-32 of a deflated entry's data once inflated; false when it does not inflate to
// exactly `size` bytes, or claims more than deflate can expand `packed` bytes to (1032:1).
bool inflated_crc(const char* data, size_t packed, size_t size, uint32_t& crc) {
  if (size > 1032 * packed + 64) return false;
  std::vector<unsigned char> out(size + 1);
  z_stream s{};
  if (inflateInit2(&s, -MAX_WBITS) != Z_OK) return false;  // raw deflate, as zip stores it
  s.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data));
  s.avail_in = static_cast<uInt>(packed);
  s.next_out = out.data();
  s.avail_out = static_cast<uInt>(out.size());
  const int rc = inflate(&s, Z_FINISH);
  const size_t produced = s.total_out;
  inflateEnd(&s);
  if (rc != Z_STREAM_END || produced != size) return false;
  crc = lfnet::crc32(out.data(), size);
  return true;
}
#endif

}  // namespace

uint32_t crc32(const void* data, size_t size, uint32_t crc) {
  const auto& t = crc_table();
  const auto* p = static_cast<const uint8_t*>(data);
  crc = ~crc;
  for (size_t i = 0; i < size; ++i) crc = t[(crc ^ p[i]) & 0xFFu] ^ (crc >> 8);
  return ~crc;
}

bool zip_checks_deflated() {
#ifdef LFNET_HAVE_ZLIB
  return true;
#else
  return false;
#endif
}

void check_zip_integrity(const std::string& path, const std::string& what) {
  std::ifstream in(path, std::ios::binary);
  LFNET_CHECK_AS(IoError, in.good(), "cannot read ", what, ": no such file or not readable");
  const std::string b((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  auto damaged = [&](const std::string& detail) {
    return CheckpointError(what + " is damaged or truncated (" + detail + ")");
  };
  // The end-of-central-directory record: the last signature within the final 64 kB + 22 bytes.
  if (b.size() < 22) throw damaged("too short for a zip archive");
  size_t end = std::string::npos;
  const size_t lowest = b.size() > 65557 ? b.size() - 65557 : 0;
  for (size_t at = b.size() - 22 + 1; at-- > lowest;) {
    if (u32(b, at) == kEndOfCentral) {
      end = at;
      break;
    }
  }
  if (end == std::string::npos) throw damaged("no zip directory at its end");
  const uint16_t entries = u16(b, end + 10);
  const uint32_t dir_size = u32(b, end + 12), dir_offset = u32(b, end + 16);
  if (dir_offset == kZip64 || dir_size == kZip64) return;  // zip64: left to LibTorch
  if (static_cast<uint64_t>(dir_offset) + dir_size > end) throw damaged("a bad zip directory");
  size_t at = dir_offset;
  for (uint16_t i = 0; i < entries; ++i) {
    if (at + 46 > end || u32(b, at) != kCentralHeader) throw damaged("a bad zip directory entry");
    const uint16_t method = u16(b, at + 10);
    const uint32_t crc = u32(b, at + 16), packed = u32(b, at + 20), size = u32(b, at + 24);
    const uint16_t name_len = u16(b, at + 28), extra_len = u16(b, at + 30),
                   comment_len = u16(b, at + 32);
    const uint32_t local = u32(b, at + 42);
    if (at + 46 + name_len > end) throw damaged("a bad zip directory entry");
    const std::string name = b.substr(at + 46, name_len);
    at += 46 + static_cast<size_t>(name_len) + extra_len + comment_len;
    if (packed == kZip64 || size == kZip64 || local == kZip64) continue;
    if (static_cast<uint64_t>(local) + 30 > b.size() || u32(b, local) != kLocalHeader) {
      throw damaged("entry " + name + " has no local header");
    }
    const size_t data = local + 30 + static_cast<size_t>(u16(b, local + 26)) + u16(b, local + 28);
    if (static_cast<uint64_t>(data) + packed > b.size()) throw damaged("entry " + name + " is cut");
    if (method == kStored) {
      if (packed != size) throw damaged("entry " + name + " has inconsistent sizes");
      if (crc32(b.data() + data, size) != crc) throw damaged("checksum mismatch in entry " + name);
    } else if (method == kDeflated) {
#ifdef LFNET_HAVE_ZLIB
      uint32_t got = 0;
      if (!inflated_crc(b.data() + data, packed, size, got)) {
        throw damaged("entry " + name + " does not inflate");
      }
      if (got != crc) throw damaged("checksum mismatch in entry " + name);
#endif
    } else {
      throw damaged("entry " + name + " uses compression method " + std::to_string(method));
    }
  }
}

}  // namespace lfnet
