// Text helpers (core/text.h) and the process clock (core/process_time.h).
#include "lfnet/core/text.h"

#include <catch2/catch.hpp>

#include <chrono>
#include <thread>

#include "lfnet/core/process_time.h"

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
  CHECK(lfnet::replace_all("d/.t1/x and d/.t1/y", "d/.t1", "d/out") == "d/out/x and d/out/y");
  CHECK(lfnet::replace_all("aaa", "a", "aa") == "aaaaaa");  // replacements are not rescanned
}

TEST_CASE("process_seconds counts from the start of the process", "[core][time]") {
  const double a = lfnet::process_seconds();
  CHECK(a >= 0);
  CHECK(a < 3600);  // this test process started moments ago, not before the machine booted
  std::this_thread::sleep_for(std::chrono::milliseconds(120));
  const double b = lfnet::process_seconds();
  // /proc's start time has a resolution of one clock tick (10 ms): the sleep shows.
  CHECK(b - a >= 0.08);
  CHECK(b - a < 5);
}
