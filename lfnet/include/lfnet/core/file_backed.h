// Large tensors held in a temporary file rather than in anonymous memory, so that a phase that
// does not read them can give their pages back (docs/reconstruction.md, "Large light fields in a
// temporary file").
//
// The file is created in $TMPDIR, else /var/tmp, else /tmp (the first that is on a disk, not in
// memory: tmpfs would hold the pages in memory all the same), unlinked at once, its blocks
// reserved (a full disk fails here, not on a later write into the mapping) and mapped shared:
// the tensor reads and writes memory as any other, and the system keeps the pages in its file
// cache while memory allows, writing them to the disk when it needs the memory. LFNET_FILE_BACKED=0
// in the environment keeps every tensor in memory.
#pragma once

#include <torch/types.h>

#include <cstddef>

namespace lfnet {

// Tensors at least this large are file-backed by default: a 5 x 5 light field of about
// 5 megapixels per view in 16-bit codes.
constexpr size_t kFileBackedMinBytes = size_t{256} << 20;

// The size from which the defaults below file-back a tensor: kFileBackedMinBytes unless set
// (tests set it low to exercise the file-backed paths on small light fields).
size_t file_backed_threshold();
void set_file_backed_threshold(size_t bytes);

// An uninitialised contiguous CPU tensor of `sizes` and `dtype`: file-backed when it has at
// least `min_bytes` and a disk-backed temporary folder can hold it, otherwise torch::empty.
torch::Tensor file_backed_empty(at::IntArrayRef sizes, at::ScalarType dtype,
                                size_t min_bytes = file_backed_threshold());

// `t` contiguous and, when it has at least `min_bytes`, file-backed: `t` itself where it already
// is, else a copy (file_backed_empty's, so ordinary memory where no folder can hold it).
torch::Tensor file_backed_copy(const torch::Tensor& t, size_t min_bytes = file_backed_threshold());

// Whether `t`'s storage is a mapping made by file_backed_empty.
bool file_backed(const torch::Tensor& t);

// Takes the pages that `t` spans (a tensor, or a view of one: a view of the light field, a band
// of its rows) out of this process's memory: their contents stay in the file and come back, from
// the file cache or the disk, when they are next read or written. Nothing for a tensor that is
// not file-backed. Only pages wholly inside the span go.
void page_out(const torch::Tensor& t);

}  // namespace lfnet
