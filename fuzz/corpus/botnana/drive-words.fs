1 1 drive-sw@ . 2 1 drive-dins@ . 1 2 drive-on? . 1 1 drive-fault? . 1 1 drive-nl? .
1 1 +drive-halt 1 1 -drive-halt 1 1 +drive-homed 1 1 drive-homed? .
4 1 1 pds-goal! 1 1 drive-emcy@ .
