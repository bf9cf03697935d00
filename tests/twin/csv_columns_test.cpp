// Tests twin/csv_columns: a header and numeric rows read back by column, empty or text cells as
// NaN, short rows padded with NaN, and the errors naming the file or the missing column.
#include "twin/csv_columns.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "tests/support/temp_dir.hpp"

namespace omnitwin::twin {
namespace {

TEST(CsvColumns, ReadsColumnsByName) {
  omnitwin::testing::TempDir dir("csvcols");
  const auto f = (dir / "t.csv").string();
  std::ofstream(f) << "t,x,name\n0,1.5,a\n0.01,-2e-3,\n0.02\n";
  const CsvColumns c = read_csv_columns(f);
  EXPECT_EQ(c.names, (std::vector<std::string>{"t", "x", "name"}));
  ASSERT_EQ(c.rows(), 3u);
  EXPECT_DOUBLE_EQ(c.column("x")[1], -2e-3);
  EXPECT_TRUE(std::isnan(c.column("name")[0]));
  EXPECT_TRUE(std::isnan(c.column("x")[2]));  // a short row
  EXPECT_THROW(
      {
        try {
          (void)c.column("y");
        } catch (const std::runtime_error& e) {
          EXPECT_NE(std::string(e.what()).find("has no column y"), std::string::npos);
          throw;
        }
      },
      std::runtime_error);
  EXPECT_THROW(read_csv_columns((dir / "missing.csv").string()), std::runtime_error);
}

}  // namespace
}  // namespace omnitwin::twin
