// SPDX-License-Identifier: LGPL-2.1-or-later
// FieldOutput (output/field_output.h): the choice of the field file format. `auto` writes
// VTU up to 16 ranks and HDF5/XDMF from 17 on (one .vtu per rank per output is thousands of
// files there); an explicit choice holds at any rank count. The files themselves are checked
// by the scene tests regression.field_output.* (tests/support/check_fields.py).
#include <shard/output/field_output.h>

#include <gtest/gtest.h>

namespace
{
  using shard::output::FieldOutput;

  TEST(FieldOutput, AutoFormatSwitchesToHdf5Above16Ranks)
  {
    EXPECT_EQ(FieldOutput::resolve_format("auto", 1), "vtu");
    EXPECT_EQ(FieldOutput::resolve_format("auto", 16), "vtu");
    EXPECT_EQ(FieldOutput::resolve_format("auto", 17), "hdf5");
    EXPECT_EQ(FieldOutput::resolve_format("auto", 4096), "hdf5");
  }

  TEST(FieldOutput, ExplicitFormatHoldsAtAnyRankCount)
  {
    for (const unsigned int n : {1u, 16u, 17u, 1024u})
      {
        EXPECT_EQ(FieldOutput::resolve_format("vtu", n), "vtu");
        EXPECT_EQ(FieldOutput::resolve_format("hdf5", n), "hdf5");
      }
  }

  TEST(FieldOutput, FormatIsADeclaredParameterWithDefaultAuto)
  {
    dealii::ParameterHandler prm;
    FieldOutput              output;
    output.declare_parameters(prm);
    prm.enter_subsection("K - Output");
    EXPECT_EQ(prm.get("format"), "auto");
    EXPECT_NO_THROW(prm.set("format", "hdf5"));
    EXPECT_ANY_THROW(prm.set("format", "h5"));
    prm.leave_subsection();
  }
} // namespace
