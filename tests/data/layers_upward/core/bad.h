// Fixture for LayeringCheckCatchesAnUpwardInclude: core must not include render.
#pragma once
#include "render/render.h"
