// Text helpers (core/text.h).
#include "lfnet/core/text.h"

#include <catch2/catch.hpp>

#include "lfnet/core/error.h"

TEST_CASE("source locations leave messages, the rest of the text stays", "[core][text]") {
  using lfnet::without_source_locations;
  CHECK(without_source_locations("bad view [/src/lfnet/src/io/light_field_io.cc:296]") ==
        "bad view");
  CHECK(without_source_locations("a [x.h:1] b [my dir/y.cpp:22]: c") == "a b: c");
  // Brackets that are no source location stay.
  CHECK(without_source_locations("files [a, b] and [notes.txt:3] and [x.cc:1a]") ==
        "files [a, b] and [notes.txt:3] and [x.cc:1a]");
  // What LFNET_CHECK appends is what goes.
  try {
    LFNET_CHECK_AS(lfnet::IoError, false, "view ", 3, " is missing");
  } catch (const lfnet::IoError& e) {
    CHECK(without_source_locations(e.what()) == "view 3 is missing");
  }
  CHECK(lfnet::join({"a", "b", "c"}, ", ") == "a, b, c");
}
